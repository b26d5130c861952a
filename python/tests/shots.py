"""Shots of one garment in each layer structure a studio's USD has, for the composition tests
(test_compose.py with usd-core, test_blender_host.py with Blender's own ``pxr``): the garment
defined in the shot's root layer (a converted pattern, or an inline mesh with its own points,
topology and texture coordinates), referenced, under a payload, or in a sublayer. Each is
made from ``samples/sheet_three_balls.usda``; the garment stays at ``GARMENT``."""

import pathlib
import shutil

from pxr import Sdf, Usd, UsdGeom, Vt

ROOT = pathlib.Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples" / "sheet_three_balls.usda"
GARMENT = "/World/Garments/sheet"
STRUCTURES = ("root_pattern", "root_mesh", "reference", "payload", "sublayer")


def _inline_mesh(path: pathlib.Path) -> None:
    """The sample with its pattern garment replaced, in the root layer, by a 20 mm grid mesh of
    the same sheet: points, quads, normals and texture coordinates of its own."""
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath(GARMENT)
    stage.RemovePrim(f"{GARMENT}/sheet")
    prim.SetTypeName("Mesh")
    n, size = 26, 0.5
    pts, st, counts, indices = [], [], [], []
    for j in range(n):
        for i in range(n):
            u, v = i / (n - 1), j / (n - 1)
            pts.append((-0.25 + size * u, 0.32, 0.25 - size * v))
            st.append((u, v))
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            counts.append(4)
            indices += [a, a + 1, a + n + 1, a + n]
    mesh = UsdGeom.Mesh(prim)
    mesh.CreatePointsAttr(Vt.Vec3fArray(pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray(counts))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(indices))
    mesh.CreateNormalsAttr(Vt.Vec3fArray([(0.0, 1.0, 0.0)] * len(pts)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    UsdGeom.PrimvarsAPI(prim).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    ).Set(Vt.Vec2fArray(st))
    stage.GetRootLayer().Save()


def _root_over(out: pathlib.Path, arc: str) -> None:
    """A shot whose root layer brings in the sample's ``/World`` by ``arc``."""
    sample = Sdf.Layer.FindOrOpen(str(SAMPLE))
    root = Sdf.Layer.CreateNew(str(out))
    for key in ("metersPerUnit", "upAxis", "timeCodesPerSecond", "framesPerSecond",
                "startTimeCode", "endTimeCode"):
        root.pseudoRoot.SetInfo(key, sample.pseudoRoot.GetInfo(key))
    if arc == "sublayer":
        root.subLayerPaths.append("./asset.usda")
    else:
        root.defaultPrim = "World"
        stage = Usd.Stage.Open(root)
        world = stage.DefinePrim("/World", "Xform")
        if arc == "reference":
            world.GetReferences().AddReference("./asset.usda")
        else:
            world.GetPayloads().AddPayload("./asset.usda")
    root.Save()


def make(structure: str, folder: pathlib.Path) -> pathlib.Path:
    """Writes the shot of ``structure`` (one of ``STRUCTURES``) in ``folder``; returns it."""
    folder.mkdir(parents=True, exist_ok=True)
    shot = folder / "shot.usda"
    if structure in ("root_pattern", "root_mesh"):
        shutil.copyfile(SAMPLE, shot)
        if structure == "root_mesh":
            _inline_mesh(shot)
    else:
        shutil.copyfile(SAMPLE, folder / "asset.usda")
        _root_over(shot, structure)
    return shot
