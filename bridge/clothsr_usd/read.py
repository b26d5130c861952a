"""Reading USD stages into plain numpy arrays, in metres with y up.

* UsdGeom meshes: topology, `primvars:st`, and points at every time sample (point caches), in
  world space (parent transforms applied at each time).
* UsdSkel avatars: skinned by pxr itself (``UsdSkel.Cache`` + ``SkinningQuery``) at every time code.
* clothsr garments (``ClothsrGarmentAPI``, or ``ClothGarmentAPI`` of schema version 0): fabric,
  panels (``ClothsrPanel``) and seams (``ClothsrSeam``).
* Fabric also from a physics material bound to the garment with OpenUSD's deformable-physics
  names (``PhysicsSurfaceDeformableMaterialAPI``, as Newton reads them); a mesh with
  ``PhysicsSurfaceDeformableSimAPI`` is cloth. clothsr's own attributes win where both are
  authored; a disagreement is reported in the stage's ``warnings``.
"""
import math

import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdPhysics, UsdShade, UsdSkel, Vt

from .common import GARMENT_API, PANEL, SEAM, BadInput, open_stage, stage_frame, units_assumed

FABRIC_ATTRS = {
    "name": "clothsr:fabric:name",
    "areal_density_kg_m2": "clothsr:fabric:arealDensity",
    "stretch_warp_n_m": "clothsr:fabric:stretchWarp",
    "stretch_weft_n_m": "clothsr:fabric:stretchWeft",
    "shear_n_m": "clothsr:fabric:shear",
    "bending_n_m": "clothsr:fabric:bending",
    "thickness_m": "clothsr:fabric:thickness",
    "damping_s": "clothsr:fabric:damping",
}
# The schema's fallbacks (cotton), for version-0 stages, where the type is not registered.
FABRIC_FALLBACK = {
    "name": "cotton",
    "areal_density_kg_m2": 0.13,
    "stretch_warp_n_m": 2500.0,
    "stretch_weft_n_m": 1800.0,
    "shear_n_m": 100.0,
    "bending_n_m": 1e-05,
    "thickness_m": 0.00035,
    "damping_s": 0.0002,
}
# OpenUSD's deformable-physics proposal, as Newton reads it.
SURFACE_SIM_API = "PhysicsSurfaceDeformableSimAPI"
SURFACE_MATERIAL_API = "PhysicsSurfaceDeformableMaterialAPI"
PHYSICS_PURPOSE = "physics"


def _matrix(m: Gf.Matrix4d) -> np.ndarray:
    return np.array(m, dtype=np.float64).reshape(4, 4)


def _to_world(points: np.ndarray, xf: np.ndarray, mpu: float, axes: np.ndarray) -> np.ndarray:
    """Row-vector points through a USD 4x4, then units and axes."""
    p = points.astype(np.float64) @ xf[:3, :3] + xf[3, :3]
    return ((p * mpu) @ axes.T).astype(np.float32)


def _has_api(prim: Usd.Prim, names) -> bool:
    """Whether ``prim`` has one of the applied API schemas ``names`` (a name or a tuple)."""
    names = (names,) if isinstance(names, str) else names
    # USD lists only registered schemas as applied; the authored list op also holds others
    # (version-0 names, the deformable-physics proposal's, which usd-core does not define).
    applied = set(prim.GetAppliedSchemas())
    op = prim.GetMetadata("apiSchemas")
    if op:
        applied.update(str(n) for n in op.ApplyOperations([]))
    return any(n in applied for n in names)


def _time_codes(stage: Usd.Stage):
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    if end < start:
        return [start]
    return [float(t) for t in np.arange(math.floor(start), math.floor(end) + 1)]


def _xform_varies(prim: Usd.Prim) -> bool:
    p = prim
    while p and not p.IsPseudoRoot():
        if p.IsA(UsdGeom.Xformable) and UsdGeom.Xformable(p).TransformMightBeTimeVarying():
            return True
        p = p.GetParent()
    return False


def _topology(mesh: UsdGeom.Mesh, path: str):
    prim_path = mesh.GetPath()
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int32)
    indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int32)
    if counts.size == 0:
        raise BadInput(f"{path}: mesh {prim_path} has no faces")
    if counts.min() < 3:
        raise BadInput(f"{path}: mesh {prim_path} has a face with fewer than 3 vertices")
    if int(counts.sum()) != indices.size:
        raise BadInput(
            f"{path}: mesh {prim_path}: faceVertexCounts sum to {int(counts.sum())} "
            f"but there are {indices.size} faceVertexIndices"
        )
    return counts, indices


def _st(mesh: UsdGeom.Mesh, n_points: int, n_corners: int, path: str):
    pv = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    if not pv or not pv.HasValue():
        return None, None
    interp = pv.GetInterpolation()
    values = np.asarray(pv.ComputeFlattened(), dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != 2:
        raise BadInput(f"{path}: {mesh.GetPath()} primvars:st is not a 2-component array")
    expect = {"vertex": n_points, "varying": n_points, "faceVarying": n_corners}.get(interp)
    if expect is None:
        raise BadInput(f"{path}: {mesh.GetPath()} primvars:st has unsupported interpolation '{interp}'")
    if values.shape[0] != expect:
        raise BadInput(
            f"{path}: {mesh.GetPath()} primvars:st has {values.shape[0]} values, "
            f"expected {expect} for '{interp}' interpolation"
        )
    if not np.isfinite(values).all():
        raise BadInput(f"{path}: {mesh.GetPath()} primvars:st has non-finite values")
    return values, ("faceVarying" if interp == "faceVarying" else "vertex")


def _skinned_prims(stage: Usd.Stage):
    """{mesh prim path: (skinning query, skeleton query, skeleton prim)} for every skinned mesh."""
    out = {}
    cache = UsdSkel.Cache()
    for prim in stage.Traverse():
        if not prim.IsA(UsdSkel.Root):
            continue
        root = UsdSkel.Root(prim)
        cache.Populate(root, Usd.PrimDefaultPredicate)
        for binding in cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate):
            skel = binding.GetSkeleton()
            skel_query = cache.GetSkelQuery(skel)
            for target in binding.GetSkinningTargets():
                if target.GetPrim().IsA(UsdGeom.Mesh):
                    out[target.GetPrim().GetPath()] = (target, skel_query, skel.GetPrim())
    return out


def _skin_problem(target, skel_query) -> str:
    """Why UsdSkel could not skin ``target``, in words, where it can be told."""
    indices = target.GetJointIndicesPrimvar().Get() if target.GetJointIndicesPrimvar() else None
    order = target.GetJointOrder() or skel_query.GetJointOrder()
    if indices is not None and len(indices) and order is not None:
        top = int(np.max(np.asarray(indices)))
        if top >= len(order) or int(np.min(np.asarray(indices))) < 0:
            return f": primvars:skel:jointIndices holds joint {top}, the skeleton has {len(order)} joints"
    return ""


def _unbound_skinned_meshes(stage: Usd.Stage, bound, path: str):
    """A mesh with skinning weights whose ``skel:skeleton`` binding resolves to no Skeleton is
    an error (USD only warns and leaves the body unskinned)."""
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh) or prim.GetPath() in bound:
            continue
        binding = UsdSkel.BindingAPI(prim)
        if not prim.HasAPI(UsdSkel.BindingAPI) or not binding.GetJointIndicesPrimvar().HasAuthoredValue():
            continue
        targets = []
        for p in prim.GetPath().GetPrefixes()[::-1]:
            rel = stage.GetPrimAtPath(p).GetRelationship("skel:skeleton")
            if rel and rel.GetTargets():
                targets = rel.GetTargets()
                break
        skel = stage.GetPrimAtPath(targets[0]) if targets else None
        if not skel or not skel.IsA(UsdSkel.Skeleton):
            raise BadInput(
                f"{path}: mesh {prim.GetPath()} has skinning weights but its skel:skeleton "
                f"({', '.join(str(t) for t in targets) or 'none'}) is not a Skeleton on the stage"
            )


def _mesh_role(prim: Usd.Prim, skinned: bool) -> str:
    if _has_api(prim, GARMENT_API + (SURFACE_SIM_API,)):
        return "cloth"
    if skinned or _has_api(prim, "PhysicsCollisionAPI"):
        return "collider"
    return "other"


def _read_mesh(stage, prim, skin, path, mpu, axes, animation: bool, warnings: list):
    mesh = UsdGeom.Mesh(prim)
    counts, indices = _topology(mesh, path)
    points_attr = mesh.GetPointsAttr()
    rest = points_attr.Get(Usd.TimeCode.Default())
    if rest is None and points_attr.GetNumTimeSamples() > 0:
        rest = points_attr.Get(points_attr.GetTimeSamples()[0])
    if rest is None or len(rest) == 0:
        raise BadInput(f"{path}: mesh {prim.GetPath()} has no points")
    n = len(rest)
    if indices.max() >= n or indices.min() < 0:
        raise BadInput(f"{path}: mesh {prim.GetPath()}: a face index is outside the {n} points")
    if skin is not None:
        times = _time_codes(stage)
    elif points_attr.GetNumTimeSamples() > 0:
        times = [float(t) for t in points_attr.GetTimeSamples()]
    elif _xform_varies(prim):
        times = _time_codes(stage)
    else:
        times = [Usd.TimeCode.Default()]
    info = {
        "path": str(prim.GetPath()),
        "name": prim.GetName(),
        "role": _mesh_role(prim, skin is not None),
        "skinned": skin is not None,
        "num_points": n,
        "num_faces": int(counts.size),
        "num_frames": len(times),
        "times": np.array(
            [0.0 if isinstance(t, Usd.TimeCode) else t for t in times], dtype=np.float64
        ),
    }
    if not animation:
        return info
    xcache = UsdGeom.XformCache()
    frames = np.empty((len(times), n, 3), dtype=np.float32)
    for k, t in enumerate(times):
        tc = t if isinstance(t, Usd.TimeCode) else Usd.TimeCode(t)
        xcache.SetTime(tc)
        if skin is not None:
            target, skel_query, skel_prim = skin
            pts = Vt.Vec3fArray(rest)
            xforms = skel_query.ComputeSkinningTransforms(tc)
            if not target.ComputeSkinnedPoints(xforms, pts, tc):
                raise BadInput(f"{path}: cannot skin {prim.GetPath()} at time {t}{_skin_problem(target, skel_query)}")
            xf = _matrix(xcache.GetLocalToWorldTransform(skel_prim))
        else:
            pts = points_attr.Get(tc)
            if pts is None or len(pts) != n:
                raise BadInput(
                    f"{path}: mesh {prim.GetPath()} has {0 if pts is None else len(pts)} points "
                    f"at time {t}, expected {n}"
                )
            xf = _matrix(xcache.GetLocalToWorldTransform(prim))
        arr = np.asarray(pts, dtype=np.float32)
        if not np.isfinite(arr).all():
            raise BadInput(f"{path}: mesh {prim.GetPath()} has non-finite points at time {t}")
        frames[k] = _to_world(arr, xf, mpu, axes)
    st, st_interp = _st(mesh, n, int(indices.size), path)
    info.update(counts=counts, indices=indices, frames=frames, st=st, st_interp=st_interp)
    pid = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("clothsr:panelId")
    info["panel_ids"] = (
        np.asarray(pid.ComputeFlattened(), dtype=np.int32) if pid and pid.HasValue() else None
    )
    seam_attr = prim.GetAttribute("clothsr:seamPairs")
    seams = seam_attr.Get() if seam_attr and seam_attr.HasValue() else None
    info["seam_pairs"] = (
        np.asarray(seams, dtype=np.int32).reshape(-1, 2) if seams is not None else None
    )
    info["fabric"] = _fabric(prim, path, mpu, warnings) if info["role"] == "cloth" else None
    return info


def _authored(prim: Usd.Prim, name: str):
    attr = prim.GetAttribute(name)
    return attr.Get() if attr and attr.HasAuthoredValue() else None


def _physics_fabric(prim: Usd.Prim, path: str, mpu: float):
    """The fabric as the bound physics material says it in OpenUSD's deformable-physics names
    ({key: value} of what it authors, in SI), and the material's path; ({}, None) without one."""
    material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(PHYSICS_PURPOSE)
    if not material or not _has_api(material.GetPrim(), SURFACE_MATERIAL_API):
        return {}, None
    mat = material.GetPrim()
    stage = prim.GetStage()
    kpu = float(UsdPhysics.GetStageKilogramsPerUnit(stage))

    def get(name, scale):
        value = _authored(mat, f"physics:{name}")
        if value is None:
            return None
        value = float(value)
        if not math.isfinite(value) or value < 0:
            raise BadInput(f"{path}: physics material {mat.GetPath()}: physics:{name} = {value}")
        return value * scale

    # Stage units to SI: density kg/m³; stiffnesses per unit length (N/m = kg/s²) scale with
    # mass only; bending (N·m) with mass and length squared; Young's modulus (Pa) with mass per
    # length.
    density = get("density", kpu / mpu**3)
    youngs = get("youngsModulus", kpu / mpu)
    poisson = get("poissonsRatio", 1.0)
    stretch = get("surfaceStretchStiffness", kpu)
    shear = get("surfaceShearStiffness", kpu)
    bend = get("surfaceBendStiffness", kpu * mpu**2)
    thickness = None
    thick = _authored(prim, "physics:thicknesses")
    if thick is not None and len(thick) > 0:
        values = np.asarray(thick, dtype=np.float64)
        if not (np.isfinite(values).all() and (values > 0).all()):
            raise BadInput(f"{path}: {prim.GetPath()}: physics:thicknesses must be positive")
        thickness = float(values.mean()) * mpu
    out = {"name": mat.GetName()}
    if thickness is not None:
        out["thickness_m"] = thickness
    # The thickness that turns density into areal density: the physics one, else clothsr's own
    # (a pattern garment has no mesh to carry physics:thicknesses), else the fallback.
    own = _authored(prim, FABRIC_ATTRS["thickness_m"])
    if thickness is not None:
        t = thickness
    elif own is not None and math.isfinite(float(own)) and float(own) > 0:
        t = float(own)  # clothsr's fabric attributes are SI
    else:
        t = FABRIC_FALLBACK["thickness_m"]
    if density is not None:
        out["areal_density_kg_m2"] = density * t
    nu = poisson if poisson is not None and poisson < 0.5 else 0.0
    if stretch is None and youngs is not None:
        stretch = youngs * t
    if shear is None and youngs is not None:
        shear = youngs * t / (2.0 * (1.0 + nu))
    if bend is None and youngs is not None:
        bend = youngs * t**3 / (12.0 * (1.0 - nu * nu))
    if stretch is not None:
        out["stretch_warp_n_m"] = out["stretch_weft_n_m"] = stretch
    if shear is not None:
        out["shear_n_m"] = shear
    if bend is not None:
        out["bending_n_m"] = bend
    return out, mat.GetPath()


def _fabric(prim: Usd.Prim, path: str, mpu: float, warnings: list) -> dict:
    """clothsr's fabric attributes where authored, else the bound physics material's, else the
    schema's fallbacks. Where both are authored and disagree, clothsr's win, with a warning."""
    own = {}
    for key, attr_name in FABRIC_ATTRS.items():
        value = _authored(prim, attr_name)
        if value is not None:
            own[key] = str(value) if key == "name" else float(value)
    physics, material = _physics_fabric(prim, path, mpu)
    if own and physics:
        compare = dict(physics)
        compare.pop("name", None)
        if "stretch_warp_n_m" in compare:
            # One surface stretch stiffness stands for clothsr's mean of warp and weft.
            stretch = compare.pop("stretch_warp_n_m")
            compare.pop("stretch_weft_n_m")
            if "stretch_warp_n_m" in own and "stretch_weft_n_m" in own:
                mine = 0.5 * (own["stretch_warp_n_m"] + own["stretch_weft_n_m"])
                compare["stretch (mean of warp and weft)"] = (stretch, mine)
        for key, value in list(compare.items()):
            if isinstance(value, tuple):
                theirs, mine = value
            elif key in own:
                theirs, mine = value, own[key]
            else:
                continue
            if abs(theirs - mine) > 1e-4 * max(abs(theirs), abs(mine)):
                warnings.append(
                    f"{path}: garment {prim.GetPath()}: its physics material {material} gives "
                    f"{key} {theirs:.6g} but its clothsr:fabric attributes {mine:.6g}; clothsr's "
                    "are used"
                )
    out = {}
    for key in FABRIC_ATTRS:
        if key in own:
            out[key] = own[key]
        elif key in physics:
            out[key] = physics[key]
        else:
            attr = prim.GetAttribute(FABRIC_ATTRS[key])
            value = attr.Get() if attr else None
            value = FABRIC_FALLBACK[key] if value is None else value
            out[key] = str(value) if key == "name" else float(value)
    edge = prim.GetAttribute("clothsr:edgeLength")
    out["edge_length_m"] = float(edge.Get()) if edge and edge.Get() is not None else 0.0
    return out


def _euler_xyz(r: np.ndarray):
    """Angles (deg) with r = Rz(c) Ry(b) Rx(a) (column vectors): x applied first, USD rotateXYZ."""
    b = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    if abs(r[2, 0]) < 1.0 - 1e-12:
        a = math.atan2(r[2, 1], r[2, 2])
        c = math.atan2(r[1, 0], r[0, 0])
    else:  # gimbal lock: put everything in a
        a = math.atan2(-r[1, 2], r[1, 1])
        c = 0.0
    return [math.degrees(a), math.degrees(b), math.degrees(c)]


def _panel_placement(prim: Usd.Prim, mpu: float, axes: np.ndarray, path: str):
    xformable = UsdGeom.Xformable(prim)
    ops = xformable.GetOrderedXformOps()
    parent_world = _matrix(
        UsdGeom.XformCache().GetParentToWorldTransform(prim)
    )
    simple = (
        [op.GetOpType() for op in ops]
        == [UsdGeom.XformOp.TypeTranslate, UsdGeom.XformOp.TypeRotateXYZ]
        and np.allclose(parent_world, np.eye(4))
        and mpu == 1.0
        and np.allclose(axes, np.eye(3))
    )
    if simple:
        t = np.array(ops[0].Get(), dtype=np.float64)
        rot = np.array(ops[1].Get(), dtype=np.float64)
        return t.tolist(), rot.tolist()
    # The local transform from the ops and the parent's: it holds for version-0 panels too,
    # whose unregistered type USD does not know as Xformable.
    world = _matrix(xformable.GetLocalTransformation(Usd.TimeCode.Default())) @ parent_world
    rot = axes @ world[:3, :3].T
    scale = np.linalg.norm(rot, axis=0)
    if not np.allclose(scale, 1.0, atol=1e-6):
        raise BadInput(f"{path}: panel {prim.GetPath()} is scaled (scale {scale}); panels must be rigidly placed")
    t = axes @ (world[3, :3] * mpu)
    return t.tolist(), _euler_xyz(rot)


def _read_garment(prim: Usd.Prim, path: str, mpu: float, axes: np.ndarray, warnings: list) -> dict:
    panels, panel_paths = [], []
    for child in prim.GetChildren():
        if child.GetTypeName() not in PANEL:
            continue
        where = f"{path}: panel {child.GetPath()}"

        def get(name, child=child, where=where):
            attr = child.GetAttribute(name)
            value = attr.Get() if attr else None
            if value is None:
                raise BadInput(f"{where}: attribute {name} is missing")
            return value

        vertices = np.asarray(get("clothsr:vertices"), dtype=np.float64).reshape(-1, 2) * mpu
        ends = np.asarray(get("clothsr:edgeEndpoints"), dtype=np.int32).reshape(-1, 2)
        types = [str(t) for t in get("clothsr:edgeCurveTypes")]
        params = np.asarray(get("clothsr:edgeCurveParams"), dtype=np.float64).reshape(-1, 4)
        if not (len(ends) == len(types) == len(params)):
            raise BadInput(
                f"{where}: {len(ends)} edgeEndpoints, {len(types)} edgeCurveTypes and "
                f"{len(params)} edgeCurveParams must match"
            )
        # Lengths scale with units: control points and radii, not flags.
        params = params.copy()
        for k, ty in enumerate(types):
            if ty in ("quadratic", "cubic"):
                params[k] *= mpu
            elif ty == "circle":
                params[k, 0] *= mpu
        translation, rotation = _panel_placement(child, mpu, axes, path)
        panels.append(
            {
                "name": child.GetName(),
                "vertices": vertices,
                "edge_endpoints": ends,
                "curve_types": types,
                "curve_params": params,
                "translation": np.array(translation, dtype=np.float64),
                "rotation": np.array(rotation, dtype=np.float64),
            }
        )
        panel_paths.append(child.GetPath())
    seams = []
    for child in prim.GetChildren():
        if child.GetTypeName() not in SEAM:
            continue
        where = f"{path}: seam {child.GetPath()}"
        side = []
        for key in ("A", "B"):
            rel = child.GetRelationship(f"clothsr:panel{key}")
            targets = rel.GetTargets() if rel else []
            if len(targets) != 1 or targets[0] not in panel_paths:
                raise BadInput(f"{where}: clothsr:panel{key} must target one panel of the garment")
            edge = child.GetAttribute(f"clothsr:edge{key}").Get()
            side.append((panel_paths.index(targets[0]), int(edge)))
        reversed_attr = child.GetAttribute("clothsr:reversed").Get()
        seams.append(
            {
                "panel_a": side[0][0],
                "edge_a": side[0][1],
                "panel_b": side[1][0],
                "edge_b": side[1][1],
                "reversed": bool(True if reversed_attr is None else reversed_attr),
            }
        )
    return {
        "path": str(prim.GetPath()),
        "name": prim.GetName(),
        "fabric": _fabric(prim, path, mpu, warnings),
        "panels": panels,
        "seams": seams,
    }


def _solver(stage: Usd.Stage, mpu: float, axes: np.ndarray):
    for prim in stage.Traverse():
        if not prim.IsA(UsdPhysics.Scene):
            continue
        scene = UsdPhysics.Scene(prim)
        direction = np.array(scene.GetGravityDirectionAttr().Get() or (0, 0, 0), dtype=np.float64)
        magnitude = scene.GetGravityMagnitudeAttr().Get()
        if np.linalg.norm(direction) == 0:
            direction = np.array([0.0, -1.0, 0.0]) if np.allclose(axes, np.eye(3)) else np.array([0.0, 0.0, -1.0])
        direction = axes @ (direction / np.linalg.norm(direction))
        g = 9.81 if magnitude is None or not math.isfinite(magnitude) or magnitude < 0 else magnitude * mpu
        dt_attr = prim.GetAttribute("clothsr:timeStep")
        dt = float(dt_attr.Get()) if dt_attr and dt_attr.Get() is not None else 1.0 / 300.0
        return {"gravity": direction * g, "dt": dt}
    return None


def _walk(path: str, animation: bool) -> dict:
    stage = open_stage(path)
    mpu, axes = stage_frame(stage, path)
    skinned = _skinned_prims(stage)
    _unbound_skinned_meshes(stage, skinned, path)
    meshes, garments, warnings = [], [], []
    assumed = units_assumed(stage)
    if assumed is not None:
        warnings.append(f"{path}: metersPerUnit is not authored: taking {assumed:g} m per unit as given")
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            meshes.append(
                _read_mesh(
                    stage, prim, skinned.get(prim.GetPath()), path, mpu, axes, animation, warnings
                )
            )
        elif _has_api(prim, GARMENT_API):
            garments.append(_read_garment(prim, path, mpu, axes, warnings))
    return {
        "meters_per_unit": mpu,
        "up_axis": str(UsdGeom.GetStageUpAxis(stage)),
        "fps": float(stage.GetTimeCodesPerSecond()),
        "start": float(stage.GetStartTimeCode()),
        "end": float(stage.GetEndTimeCode()),
        "meshes": meshes,
        "garments": garments,
        "solver": _solver(stage, mpu, axes),
        "warnings": warnings,
    }


def inspect_stage(path: str) -> dict:
    """Metadata, meshes (counts, frames, role) and garments, without loading point animation."""
    return _walk(path, animation=False)


def read_stage(path: str) -> dict:
    """Everything: meshes with all their frames (world space, metres, y up), garments, solver."""
    return _walk(path, animation=True)
