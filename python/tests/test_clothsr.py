"""The `clothsr` Python package against the built wheel, installed in a venv with no `clothsr`
binary on PATH (.ci/run: the `python` stage). Samples come from the repository."""

import os
import pathlib
import shutil
import threading
import time

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom

import clothsr

ROOT = pathlib.Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "samples" / "sheet_sphere.usda"
GARMENT = "/World/Garments/sheet"


def points(layer_or_path, prim=GARMENT):
    """{time code: points} of the prim's time samples."""
    stage = Usd.Stage.Open(layer_or_path)
    attr = UsdGeom.Mesh(stage.GetPrimAtPath(prim)).GetPointsAttr()
    return {t: np.array(attr.Get(t)) for t in attr.GetTimeSamples()}


def same(a, b):
    return a.keys() == b.keys() and all(np.array_equal(a[t], b[t]) for t in a)


def test_no_clothsr_binary_on_path():
    assert shutil.which("clothsr") is None, "the package must work without the binary"


def test_run_writes_the_fine_mesh_and_reports_progress(tmp_path):
    seen = []
    layer = clothsr.run(
        SAMPLE, tmp_path / "out.usdc", frames=4, progress=lambda d, t: seen.append((d, t))
    )
    assert isinstance(layer, Sdf.Layer)
    assert seen == [(i, 4) for i in range(5)]
    p = points(layer)
    assert sorted(p) == [0.0, 1.0, 2.0, 3.0, 4.0]
    # The fine mesh, not the coarse one: far more vertices than the 20 mm sheet's.
    assert p[4.0].shape[1] == 3 and p[4.0].shape[0] > 10_000
    assert np.isfinite(p[4.0]).all() and not np.array_equal(p[0.0], p[4.0])


@pytest.mark.skipif(
    "CLOTHSR_CLI_OUTPUT" not in os.environ,
    reason="CLOTHSR_CLI_OUTPUT (the CLI's `run samples/sheet_sphere.usda --frames 4`) not given",
)
def test_same_fine_mesh_as_the_cli_bit_for_bit(tmp_path):
    layer = clothsr.run(SAMPLE, tmp_path / "out.usdc", frames=4)
    assert same(points(layer), points(os.environ["CLOTHSR_CLI_OUTPUT"]))


def test_an_open_in_memory_stage_runs_as_its_file(tmp_path):
    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().TransferContent(Sdf.Layer.FindOrOpen(str(SAMPLE)))
    from_stage = clothsr.run(stage, tmp_path / "stage.usdc", frames=2)
    from_file = clothsr.run(SAMPLE, tmp_path / "file.usdc", frames=2)
    assert same(points(from_stage), points(from_file))
    # Without an output path, an anonymous layer comes back.
    anonymous = clothsr.run(stage, frames=1)
    assert anonymous.anonymous and len(points(anonymous)) == 2


def test_an_edited_stage_runs_with_its_edits(tmp_path):
    # Standalone: world coordinates (a layer holds the garment in its prim's own space).
    plain = points(clothsr.run(SAMPLE, tmp_path / "plain.usdc", frames=1, layer=False))
    stage = Usd.Stage.Open(str(SAMPLE))
    try:
        # Unsaved: the sheet moved 10 cm along x.
        UsdGeom.Xformable(stage.GetPrimAtPath(GARMENT)).AddTranslateOp(opSuffix="edit").Set(
            (0.1, 0.0, 0.0)
        )
        edited = points(clothsr.run(stage, tmp_path / "edited.usdc", frames=1, layer=False))
        # A layer for the edited stage names the stage's file as its shot, not the export.
        layer = clothsr.run(stage, tmp_path / "edited_layer.usda", frames=1)
        assert layer.customLayerData["clothsr:layerFor"] == os.path.relpath(SAMPLE, tmp_path)
    finally:
        # The layer is this process's: every later open of the sample would see the edit.
        stage.GetRootLayer().Reload(True)
    shift = (edited[0.0] - plain[0.0]).mean(axis=0)
    assert np.allclose(shift, [0.1, 0.0, 0.0], atol=1e-3), shift


def test_cancelled_run_keeps_its_frames_and_resumes(tmp_path):
    out = tmp_path / "out.usdc"
    with pytest.raises(clothsr.Cancelled):
        clothsr.run(SAMPLE, out, frames=4, progress=lambda d, t: d < 2)
    assert sorted(points(str(out))) == [0.0, 1.0, 2.0]
    seen = []
    clothsr.run(SAMPLE, out, frames=4, progress=lambda d, t: seen.append(d))
    assert seen[0] == 2, "the second call resumes after the published frame 2"
    straight = clothsr.run(SAMPLE, tmp_path / "straight.usdc", frames=4)
    assert same(points(str(out)), points(straight))


def test_an_exception_in_the_callback_stops_the_run_and_propagates(tmp_path):
    def progress(done, total):
        if done == 1:
            raise KeyError("stop here")

    with pytest.raises(KeyError, match="stop here"):
        clothsr.run(SAMPLE, tmp_path / "out.usdc", frames=3, progress=progress)


def test_another_thread_runs_while_clothsr_works(tmp_path):
    ticks = []
    stop = threading.Event()

    def tick():
        while not stop.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.002)

    thread = threading.Thread(target=tick)
    thread.start()
    t0 = time.monotonic()
    clothsr.run(SAMPLE, tmp_path / "out.usdc", frames=8)
    t1 = time.monotonic()
    stop.set()
    thread.join()
    assert t1 - t0 > 0.5, "the run should take long enough to measure"
    inside = [t for t in ticks if t0 + 0.2 < t < t1 - 0.1]
    # Holding the GIL for the run would leave the thread no tick in between.
    expected = (t1 - t0 - 0.3) / 0.002
    assert len(inside) > 0.2 * expected, (len(inside), expected)


def test_bad_input_raises_naming_the_file(tmp_path):
    bad = tmp_path / "broken.usda"
    bad.write_text("#usda 1.0\ndef Mesh \"cloth\" {\n")
    with pytest.raises(clothsr.BadInputError, match="broken.usda"):
        clothsr.run(bad, tmp_path / "out.usdc", frames=1)
    with pytest.raises(clothsr.UsageError, match="unknown fabric"):
        clothsr.run(SAMPLE, tmp_path / "out.usdc", fabric="tweed")
    with pytest.raises(clothsr.UsageError, match="must end in"):
        clothsr.run(SAMPLE, tmp_path / "out.txt", frames=1)
    assert issubclass(clothsr.BadInputError, clothsr.ClothsrError)
    assert not (tmp_path / "out.usdc").exists()


def test_convert_and_inspect(tmp_path):
    layer = clothsr.convert(SAMPLE, tmp_path / "scene.usda", fabric="denim", frames=10)
    stage = Usd.Stage.Open(layer)
    assert stage.GetPrimAtPath(GARMENT).IsValid()
    info = clothsr.inspect(stage)
    assert [g["name"] for g in info["garments"]] == ["sheet"]
    assert info["frame_end"] - info["frame_start"] == 10
    assert [c["name"] for c in info["colliders"]] == ["sphere"]


def test_units_a_file_does_not_state_are_given_for_the_call(tmp_path):
    no_units = ROOT / "tests/data/bad/usd/no_meters_per_unit.usda"
    with pytest.raises(clothsr.BadInputError, match="meters_per_unit"):
        clothsr.convert(no_units, tmp_path / "refused.usda")
    with pytest.raises(clothsr.UsageError, match="meters_per_unit"):
        clothsr.convert(no_units, tmp_path / "refused.usda", meters_per_unit=-1.0)
    layer = clothsr.convert(no_units, tmp_path / "scene.usda", meters_per_unit=0.01)
    stage = Usd.Stage.Open(layer)
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    sheet = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    corner = np.array(UsdGeom.Mesh(sheet).GetPointsAttr().Get(0)[0])
    assert np.allclose(corner, [-0.0015, 0.005, -0.0015], atol=1e-7)
    assert clothsr.inspect(no_units, meters_per_unit=0.01)["cloths"]
    # The units were for that call only.
    with pytest.raises(clothsr.BadInputError, match="metersPerUnit"):
        clothsr.inspect(no_units)
    assert not (tmp_path / "refused.usda").exists()


def test_eval_measures_a_run_against_itself_as_zero(tmp_path):
    out = tmp_path / "out.usdc"
    clothsr.run(SAMPLE, out, frames=2)
    e = clothsr.evaluate(out, out)
    assert e["prediction"]["frames"] >= 2 and e["prediction"]["mean_mm"] == 0.0


def test_a_host_whose_usd_loaded_first_still_reads_and_writes(tmp_path):
    """A DCC has USD loaded and stages open long before clothsr is imported: clothsr's schema
    then cannot register, and the bridge must not need it."""
    import subprocess
    import sys

    script = f"""
from pxr import Usd
Usd.Stage.Open({str(SAMPLE)!r})
import clothsr
layer = clothsr.run({str(SAMPLE)!r}, {str(tmp_path / "late.usdc")!r}, frames=1)
stage = Usd.Stage.Open(layer)
print(len(stage.GetPrimAtPath({GARMENT!r}).GetAttribute("points").GetTimeSamples()))
"""
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "2"


def test_usd_shots_get_an_override_layer_and_standalone_on_request(tmp_path):
    layer = clothsr.run(SAMPLE, tmp_path / "layer.usda", frames=1)
    assert "clothsr:layerFor" in layer.customLayerData
    specs = []
    layer.Traverse("/", lambda p: specs.append(str(p)) if p.IsPrimPath() else None)
    assert "/World/Colliders/sphere" not in specs and GARMENT in specs
    # Composed over the shot: the garment is the fine mesh, the sphere is there.
    stage = Usd.Stage.Open(str(SAMPLE))
    clothsr.compose(stage, layer)
    assert stage.GetPrimAtPath(GARMENT).GetTypeName() == "Mesh"
    assert stage.GetPrimAtPath("/World/Colliders/sphere").IsValid()
    # The CLI's words and booleans alike.
    for off in (False, "off"):
        standalone = clothsr.run(SAMPLE, tmp_path / "standalone.usdc", frames=1, layer=off)
        assert Usd.Stage.Open(standalone).GetPrimAtPath("/World/Colliders/sphere").IsValid()
    assert "clothsr:layerFor" in clothsr.run(SAMPLE, tmp_path / "on.usda", frames=1, layer="on").customLayerData
    with pytest.raises(clothsr.UsageError, match="layer='of'"):
        clothsr.run(SAMPLE, tmp_path / "bad.usda", frames=1, layer="of")


def test_a_cancelled_run_into_value_clips_resumes_to_the_same_frames(tmp_path):
    out = tmp_path / "clips.usda"
    with pytest.raises(clothsr.Cancelled):
        clothsr.run(SAMPLE, out, frames=5, clip_frames=2, progress=lambda d, t: d < 3)
    clothsr.run(SAMPLE, out, frames=5, clip_frames=2)
    assert (tmp_path / "clips.clips" / "clips.0002.usdc").exists()
    straight = clothsr.run(SAMPLE, tmp_path / "straight.usda", frames=5, clip_frames=0)
    assert same(points(str(out)), points(straight))
