"""Bakes the skinned walking avatar into a point cache, as the shared data's full bake is made.

    python tests/data/avatars/bake.py tests/data/avatars/mh_walk_train.usda OUT.usdc [END]

A plain Mesh `/Avatar/Body` with the UsdSkel skinned points (and extents) at every 2nd time
code from 0 to END (default: the clip's end), the same topology and stage metadata. The
skirt's model recipe (`samples/models/skirt/make.sh`) runs on it; the tests read the trimmed
copy `mh_walk_train_baked_2s.usdc` (first 2 s).
"""

import sys

from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt


def main(src: str, dst: str, end: float | None) -> None:
    stage = Usd.Stage.Open(src)
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.TraverseInstanceProxies())
    body = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    mesh = UsdGeom.Mesh(body)
    skinning = cache.GetSkinningQuery(body)
    skel_query = cache.GetSkelQuery(UsdSkel.BindingAPI(body).GetSkeleton())
    end = stage.GetEndTimeCode() if end is None else end

    out = Usd.Stage.CreateNew(dst)
    for key in ("framesPerSecond", "timeCodesPerSecond", "metersPerUnit", "upAxis"):
        out.SetMetadata(key, stage.GetMetadata(key))
    out.SetStartTimeCode(stage.GetStartTimeCode())
    out.SetEndTimeCode(end)
    avatar = UsdGeom.Xform.Define(out, "/Avatar")
    out.SetDefaultPrim(avatar.GetPrim())
    baked = UsdGeom.Mesh.Define(out, "/Avatar/Body")
    baked.CreateFaceVertexCountsAttr(mesh.GetFaceVertexCountsAttr().Get())
    baked.CreateFaceVertexIndicesAttr(mesh.GetFaceVertexIndicesAttr().Get())
    baked.CreateDoubleSidedAttr(False)
    baked.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    baked.CreateDisplayColorAttr([Gf.Vec3f(0.8, 0.68, 0.58)])
    rest = mesh.GetPointsAttr().Get()
    t = stage.GetStartTimeCode()
    while t <= end:
        xf = skel_query.ComputeSkinningTransforms(t)
        points = Vt.Vec3fArray(rest)
        skinning.ComputeSkinnedPoints(xf, points, t)
        baked.GetPointsAttr().Set(points, t)
        baked.GetExtentAttr().Set(UsdGeom.Mesh.ComputeExtent(points), t)
        t += 2.0
    out.GetRootLayer().Save()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]) if len(sys.argv) > 3 else None)
