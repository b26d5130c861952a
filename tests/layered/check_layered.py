"""Checks a layered output the way a TD uses it (tests/layered.rs): the layer sublayered over
the shot in a new root layer that keeps the shot's stage metadata.

    python tests/layered/check_layered.py SHOT.usda LAYER.usd FRAMES

Exits non-zero naming what failed: validators, each garment once at its own path, nothing
copied or added (the avatar once), the shot's units, up axis and time codes, and the fine
garment where the shot's garment is (in the shot's frame).
"""
import os
import sys

import numpy as np
from pxr import Sdf, Usd, UsdGeom

import clothsr_usd
from clothsr_usd.common import LAYER_FOR_KEY

failures = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        failures.append(what)


def world_points(prim, t, mpu, up):
    pts = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(t), dtype=np.float64)
    m = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(t), dtype=np.float64).reshape(4, 4)
    w = (pts @ m[:3, :3] + m[3, :3]) * mpu
    return w[:, [0, 2, 1]] * [1, 1, -1] if up == "Z" else w


def garments(stage):
    return [
        p for p in stage.Traverse()
        if p.IsA(UsdGeom.Mesh) and "ClothsrGarmentAPI" in p.GetPrimTypeInfo().GetAppliedAPISchemas()
    ]


def main() -> int:
    shot_path, layer_path, frames = sys.argv[1], sys.argv[2], int(sys.argv[3])
    shot = Usd.Stage.Open(shot_path)
    layer = Sdf.Layer.FindOrOpen(layer_path)
    for key in ("metersPerUnit", "upAxis", "timeCodesPerSecond", "framesPerSecond"):
        check(
            layer.pseudoRoot.GetInfo(key) == shot.GetRootLayer().pseudoRoot.GetInfo(key),
            f"the layer's {key} {layer.pseudoRoot.GetInfo(key)} is the shot's",
        )
    check(
        os.path.realpath(os.path.join(os.path.dirname(layer_path), layer.customLayerData[LAYER_FOR_KEY]))
        == os.path.realpath(shot_path),
        "the layer names its shot",
    )
    # Nothing of the shot but its garments is in the layer (the avatar is not copied).
    specs = []
    layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: specs.append(p) if p.IsPrimPath() else None)
    shot_garments = {str(p.GetPath()) for p in garments(shot)}
    stray = [str(p) for p in specs if not any(g.startswith(str(p)) or str(p).startswith(g) for g in shot_garments)]
    check(not stray, f"the layer holds only the garments' prims and their ancestors (stray: {stray[:5]})")

    # The composed shot written beside the layer: the documented way to use it.
    root_path = str(clothsr_usd.composed_path(layer_path))
    check(os.path.exists(root_path), f"the composed shot {root_path} is written beside the layer")
    root = Sdf.Layer.FindOrOpen(root_path)
    check(
        [os.path.realpath(os.path.join(os.path.dirname(root_path), p)) for p in root.subLayerPaths]
        == [os.path.realpath(layer_path), os.path.realpath(shot_path)],
        f"the composed shot is the layer over the shot ({list(root.subLayerPaths)})",
    )
    base = {(i, m) for s, i, m in clothsr_usd.validate(shot_path) if s == "error"}
    errors = [(i, m) for s, i, m in clothsr_usd.validate(root_path) if s == "error" and (i, m) not in base]
    check(not errors, f"usd-core's validators pass on the shot with the layer ({errors[:3]})")
    composed = Usd.Stage.Open(root_path)
    mpu = UsdGeom.GetStageMetersPerUnit(composed)
    up = UsdGeom.GetStageUpAxis(composed)
    check(
        (mpu, up) == (UsdGeom.GetStageMetersPerUnit(shot), UsdGeom.GetStageUpAxis(shot)),
        f"the composed stage keeps the shot's units and axis ({mpu}, {up})",
    )
    paths = sorted(str(p.GetPath()) for p in composed.Traverse())
    before = sorted(str(p.GetPath()) for p in shot.Traverse())
    check(set(paths) <= set(before), f"no prim added (new: {sorted(set(paths) - set(before))[:5]})")
    meshes = [p for p in composed.Traverse() if p.IsA(UsdGeom.Mesh)]
    avatar = [p for p in meshes if len(UsdGeom.Mesh(p).GetPointsAttr().Get(0) or []) == len(
        UsdGeom.Mesh(shot.GetPrimAtPath(p.GetPath())).GetPointsAttr().Get(0) or [None]
    ) and p not in garments(composed)]
    check(len(meshes) == len([p for p in shot.Traverse() if p.IsA(UsdGeom.Mesh)]), "each mesh once")
    check(len(avatar) >= 1, "the avatar is there, as the shot has it")
    for path in sorted(shot_garments):
        g = composed.GetPrimAtPath(path)
        check(g.IsValid() and g.IsA(UsdGeom.Mesh), f"{path} is the fine mesh, at its own path")
        pts_attr = UsdGeom.Mesh(g).GetPointsAttr()
        times = pts_attr.GetTimeSamples()
        check(times == [float(t) for t in range(frames + 1)], f"{path} has frames 0..{frames} ({times})")
        n = len(pts_attr.Get(frames))
        for attr in ("normals", "velocities"):
            v = g.GetAttribute(attr).Get(frames)
            check(v is not None and len(v) == n, f"{path} has {attr} per point")
        check(UsdGeom.Mesh(g).GetExtentAttr().Get(frames) is not None, f"{path} has an extent")
        check(Usd.ModelAPI(g).GetKind() != "", f"{path} has a kind")
        st = UsdGeom.PrimvarsAPI(g).GetPrimvar("st")
        check(st and len(st.ComputeFlattened()) == n, f"{path} has primvars:st per point")
        # The fine garment is on the avatar, in the shot's frame: wrong units or axes put it
        # metres away or turned.
        fine = world_points(g, Usd.TimeCode(frames), mpu, up)
        body = np.concatenate([world_points(a, Usd.TimeCode(frames), mpu, up) for a in avatar])
        centre = np.linalg.norm((fine.mean(axis=0) - body.mean(axis=0))[[0, 2]])
        height = (fine[:, 1].mean() - body[:, 1].min()) / np.ptp(body[:, 1])
        within = body[:, 1].min() <= fine[:, 1].min() and fine[:, 1].max() <= body[:, 1].max()
        check(
            centre < 0.2 and within and 0.3 < height < 0.8,
            f"{path} is on the avatar: {centre:.2f} m off its axis, at {height:.2f} of its height",
        )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
