"""A run's override layer applied to its shot by the documented recipe, in every layer structure
a shot has (shots.py): the composed shot written beside the layer, and ``clothsr.compose`` on
an open stage, both give the fine animated mesh at the garment's path and change nothing else."""

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

import clothsr
import shots

FRAMES = 2


def fine_points(stage, t):
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(shots.GARMENT))
    return np.array(mesh.GetPointsAttr().Get(t))


def layer_points(layer, t):
    return np.array(layer.QueryTimeSample(Sdf.Path(shots.GARMENT).AppendProperty("points"), t))


def rest_of(stage):
    """Every prim outside the garment, with its type and its points' first and last values."""
    out = {}
    for prim in stage.Traverse():
        if prim.GetPath().HasPrefix(shots.GARMENT):
            continue
        pts = UsdGeom.Mesh(prim).GetPointsAttr() if prim.IsA(UsdGeom.Mesh) else None
        key = (prim.GetTypeName(), str(prim.GetPath()))
        out[key] = [] if pts is None else [np.array(pts.Get(t)).tolist() for t in (0, FRAMES)]
    return out


def check(stage, layer, shot_alone, what):
    prim = stage.GetPrimAtPath(shots.GARMENT)
    assert prim and prim.GetTypeName() == "Mesh", f"{what}: the garment is {prim.GetTypeName()}"
    mesh = UsdGeom.Mesh(prim)
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get())
    indices = np.array(mesh.GetFaceVertexIndicesAttr().Get())
    for t in range(FRAMES + 1):
        pts = fine_points(stage, t)
        assert pts.shape[0] > 10_000, f"{what}: {pts.shape[0]} points at {t}, not the fine mesh's"
        assert np.array_equal(pts, layer_points(layer, t)), f"{what}: points at {t}"
    assert (counts == 3).all() and indices.max() == pts.shape[0] - 1, f"{what}: topology"
    assert [c.GetName() for c in prim.GetChildren()] == [], f"{what}: the garment keeps children"
    st = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st").Get()
    assert len(st) == pts.shape[0], f"{what}: primvars:st is not the fine mesh's"
    normals = mesh.GetNormalsAttr().Get(1)
    assert normals is not None and len(normals) == pts.shape[0], f"{what}: normals"
    assert rest_of(stage) == shot_alone, f"{what}: the rest of the shot changed"


@pytest.mark.parametrize("structure", shots.STRUCTURES)
def test_the_fine_garment_composes_in_every_shot_structure(tmp_path, structure):
    shot = shots.make(structure, tmp_path)
    shot_alone = rest_of(Usd.Stage.Open(str(shot)))
    layer = clothsr.run(shot, tmp_path / "cloth.usdc", frames=FRAMES)
    composed = tmp_path / "cloth.composed.usda"
    assert composed.exists(), "the composed shot is written beside the layer"
    assert Sdf.Layer.FindOrOpen(str(composed)).subLayerPaths == ["./cloth.usdc", "./shot.usda"]
    check(Usd.Stage.Open(str(composed)), layer, shot_alone, f"{structure}, composed file")

    stage = Usd.Stage.Open(str(shot))
    clothsr.compose(stage, layer)
    clothsr.compose(stage, layer)  # again: still once, first
    assert list(stage.GetSessionLayer().subLayerPaths) == [layer.identifier]
    check(stage, layer, shot_alone, f"{structure}, compose() on the open stage")
    assert not any(x.dirty for x in stage.GetLayerStack(includeSessionLayers=False))


def test_an_edited_stage_composes_with_its_edits(tmp_path):
    shot = shots.make("root_pattern", tmp_path)
    stage = Usd.Stage.Open(str(shot))
    UsdGeom.Xformable(stage.GetPrimAtPath(shots.GARMENT)).AddTranslateOp(opSuffix="edit").Set(
        (0.0, 0.05, 0.0)
    )
    layer = clothsr.run(stage, tmp_path / "cloth.usdc", frames=1)
    clothsr.compose(stage, layer)
    assert fine_points(stage, 1).shape[0] > 10_000
    # The composed file names the stage's saved file (without the unsaved edit).
    composed = Sdf.Layer.FindOrOpen(str(tmp_path / "cloth.composed.usda"))
    assert composed.subLayerPaths == ["./cloth.usdc", "./shot.usda"]
    # An in-memory stage has no file to compose with: no composed file.
    memory = Usd.Stage.CreateInMemory()
    memory.GetRootLayer().TransferContent(Sdf.Layer.FindOrOpen(str(shot)))
    clothsr.run(memory, tmp_path / "memory.usdc", frames=1)
    assert not (tmp_path / "memory.composed.usda").exists()


def test_compose_wants_an_open_stage(tmp_path):
    with pytest.raises(clothsr.UsageError, match="Usd.Stage"):
        clothsr.compose(str(tmp_path / "shot.usda"), "cloth.usdc")
