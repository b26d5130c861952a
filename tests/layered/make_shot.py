"""Builds a studio-style shot for clothsr's layered-output tests (tests/layered.rs): z up, in
centimetres, the walking avatar (UsdSkel, y up, metres) and a garment mesh referenced under one
transform that turns and scales them into the shot's frame.

    python tests/layered/make_shot.py SHOT.usda GARMENT.usd AVATAR.usda
"""
import os
import sys

from pxr import Gf, Usd, UsdGeom


def garment_prim(path: str) -> str:
    stage = Usd.Stage.Open(path)
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh) and "ClothsrGarmentAPI" in prim.GetPrimTypeInfo().GetAppliedAPISchemas():
            return str(prim.GetPath())
    raise SystemExit(f"{path}: no garment mesh")


def main() -> int:
    out, garment, avatar = sys.argv[1:4]
    here = os.path.dirname(os.path.abspath(out))
    stage = Usd.Stage.CreateNew(out)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    stage.SetTimeCodesPerSecond(30)
    stage.SetFramesPerSecond(30)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(60)
    shot = UsdGeom.Xform.Define(stage, "/Shot")
    stage.SetDefaultPrim(shot.GetPrim())
    # y up, metres -> z up, centimetres.
    shot.AddRotateXOp().Set(90.0)
    shot.AddScaleOp().Set(Gf.Vec3f(100.0, 100.0, 100.0))
    stage.DefinePrim("/Shot/Avatar").GetReferences().AddReference(os.path.relpath(avatar, here))
    stage.DefinePrim("/Shot/Skirt").GetReferences().AddReference(
        os.path.relpath(garment, here), garment_prim(garment)
    )
    stage.GetRootLayer().Save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
