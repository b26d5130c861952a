"""clothsr's Blender extension (dcc/blender, zipped by tools/blender_extension.py) installed into
a headless Blender (PyPI ``bpy``) the way Blender installs extensions, its bundled wheel the
only clothsr in the process: its operator runs a USD shot file and the current scene, and the
fine cloth it imports has pxr's vertices at every frame. Runs in a Python with ``bpy`` and no
clothsr, with the zip in $CLOTHSR_BLENDER_EXTENSION (.ci/python); skipped elsewhere."""

import os
import pathlib
import shutil
import sys
import tempfile

import pytest

# Blender's user folders (extensions, preferences) in a temporary place: read at `import bpy`.
_USER = tempfile.mkdtemp(prefix="clothsr-blender-user-")
os.environ["BLENDER_USER_RESOURCES"] = _USER

bpy = pytest.importorskip("bpy")
ZIP = os.environ.get("CLOTHSR_BLENDER_EXTENSION")
if not ZIP:
    pytest.skip("CLOTHSR_BLENDER_EXTENSION (the extension zip) not given", allow_module_level=True)

import numpy as np  # noqa: E402

import blender_common as common  # noqa: E402

FRAMES = 2
TOLERANCE_M = 1e-6
MODULE = "bl_ext.user_default.clothsr"


@pytest.fixture(scope="module")
def extension():
    import addon_utils

    assert "clothsr" not in sys.modules, "clothsr must come from the extension's wheel"
    result = bpy.ops.extensions.package_install_files(
        filepath=os.path.abspath(ZIP), repo="user_default", enable_on_install=True
    )
    assert "FINISHED" in result
    assert addon_utils.check(MODULE) == (True, True)
    yield
    bpy.ops.extensions.package_uninstall(
        repo_directory=bpy.utils.user_resource("EXTENSIONS", path="user_default"), pkg_id="clothsr"
    )
    shutil.rmtree(_USER, ignore_errors=True)


def empty_scene():
    """A scene with no objects, the extension still enabled (factory settings would drop it)."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for mesh in list(bpy.data.meshes):
        bpy.data.meshes.remove(mesh)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 250


def test_the_wheel_comes_with_the_extension(extension):
    import clothsr

    assert pathlib.Path(clothsr.__file__).resolve().is_relative_to(pathlib.Path(_USER).resolve())


def test_the_operator_runs_a_shot_file_and_imports_its_fine_cloth(extension, tmp_path):
    shot = common.shots.make("root_pattern", tmp_path / "shot")
    empty_scene()
    settings = bpy.context.scene.clothsr
    settings.source = "FILE"
    settings.shot = str(shot)
    settings.frames = FRAMES
    settings.output = str(tmp_path / "out")
    assert "FINISHED" in bpy.ops.clothsr.run()
    layer = tmp_path / "out" / "shot_cloth.usdc"
    assert layer.exists() and (tmp_path / "out" / "shot_cloth.composed.usda").exists()
    cloth = [o for o in bpy.context.scene.objects if o.type == "MESH" and o.name == "sheet"]
    assert len(cloth) == 1 and bpy.context.scene.frame_end == FRAMES
    from pxr import Usd

    stage = Usd.Stage.Open(str(tmp_path / "out" / "shot_cloth.composed.usda"))
    for t in range(FRAMES + 1):
        want = common.pxr_world(stage, common.shots.GARMENT, t)
        got = common.blender_world(cloth[0], t)
        assert want.shape[0] > 10_000 and got.shape == want.shape
        assert np.abs(got - want).max() <= TOLERANCE_M


def test_the_operator_runs_the_current_scene(extension, tmp_path):
    empty_scene()
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 1 + FRAMES
    # A 0.5 m sheet of 20 mm squares, 0.4 m up, above a ball.
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=25, y_subdivisions=25, size=0.5, location=(0, 0, 0.4))
    sheet = bpy.context.object
    sheet.name = "Sheet"
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.15, location=(0, 0, 0.15))
    coarse = len(sheet.data.vertices)
    before = set(scene.objects)
    settings = scene.clothsr
    settings.source = "SCENE"
    settings.garment = sheet
    settings.fabric = "denim"
    settings.output = str(tmp_path / "out")
    assert "FINISHED" in bpy.ops.clothsr.run()
    fine = [o for o in scene.objects if o.type == "MESH" and o not in before]
    assert len(fine) == 1, [o.name for o in scene.objects]
    assert sheet.hide_get() and sheet.hide_render, "the coarse garment is hidden"
    first = common.blender_world(fine[0], 1)
    last = common.blender_world(fine[0], 1 + FRAMES)
    assert first.shape[0] > 10 * coarse, "the fine mesh, not the garment's"
    # Where the sheet was, then lower: it falls.
    start = common.blender_world(sheet, 1)
    assert abs(first[:, 1].mean() - start[:, 1].mean()) < 5e-3
    assert last[:, 1].mean() < first[:, 1].mean() - 1e-3
