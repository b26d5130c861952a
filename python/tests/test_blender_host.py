"""clothsr inside Blender as a pipeline TD uses it: the wheel installed into Blender's Python
(here PyPI ``bpy``, Blender as a module), Blender's own ``pxr`` the only USD in the process.
``clothsr.run`` on a stage Blender's ``pxr`` opened, in each shot structure (shots.py), then
the composed shot imported by Blender's USD importer: its fine mesh has pxr's vertices at
every frame. Runs in a Python with ``bpy`` and the wheel, without usd-core (.ci/python);
skipped elsewhere."""

import os

import pytest

bpy = pytest.importorskip("bpy")

import numpy as np  # noqa: E402
from blender_common import SITE, blender_world, pxr_world, shots  # noqa: E402
from pxr import Usd  # noqa: E402

import clothsr  # noqa: E402

FRAMES = 2
TOLERANCE_M = 1e-6


def test_pxr_is_blenders():
    assert os.path.realpath(Usd.__file__).startswith(os.path.realpath(SITE)), "usd-core is here too"


@pytest.mark.parametrize("structure", shots.STRUCTURES)
def test_blender_imports_the_fine_cloth_pxr_composes(tmp_path, structure):
    shot = shots.make(structure, tmp_path)
    stage = Usd.Stage.Open(str(shot))
    layer = clothsr.run(stage, tmp_path / "cloth.usdc", frames=FRAMES)
    # The recipe for an open stage ...
    clothsr.compose(stage, layer)
    assert stage.GetPrimAtPath(shots.GARMENT).GetTypeName() == "Mesh"
    want = {t: pxr_world(stage, shots.GARMENT, t) for t in range(FRAMES + 1)}
    assert want[FRAMES].shape[0] > 10_000, "the fine mesh"
    # ... and for files: the composed shot, imported by Blender.
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.wm.usd_import(filepath=str(tmp_path / "cloth.composed.usda"), set_frame_range=True)
    assert "FINISHED" in result
    cloth = [o for o in bpy.context.scene.objects if o.type == "MESH" and o.name == "sheet"]
    assert len(cloth) == 1, [o.name for o in bpy.context.scene.objects]
    assert bpy.context.scene.frame_end == FRAMES
    for t, pts in want.items():
        got = blender_world(cloth[0], t)
        assert got.shape == pts.shape, f"{structure} at {t}: {got.shape} vertices, pxr {pts.shape}"
        worst = np.abs(got - pts).max()
        assert worst <= TOLERANCE_M, f"{structure} at {t}: Blender is {worst:e} m from pxr"
