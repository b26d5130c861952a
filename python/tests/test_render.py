"""tools/render.py, the Blender (bpy) renderer of clothsr's USD output: a tiny render of a scene
written here. Skipped unless Blender's Python module is there: the interpreter in
$CLOTHSR_BPY_PYTHON, else the repository's .venv-bpy (bash .ci/setup makes it)."""

import os
import pathlib
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
RENDER = ROOT / "tools" / "render.py"


def bpy_python():
    """The interpreter that imports bpy, or None."""
    path = os.environ.get("CLOTHSR_BPY_PYTHON") or str(ROOT / ".venv-bpy" / "bin" / "python")
    if not os.path.exists(path):
        return None
    try:
        ok = subprocess.run([path, "-c", "import bpy"], capture_output=True, timeout=300).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return None
    return path if ok else None


BPY = bpy_python()
pytestmark = pytest.mark.skipif(
    BPY is None, reason="no bpy: set CLOTHSR_BPY_PYTHON or run bash .ci/setup (.venv-bpy)"
)


def read_png(path):
    """8-bit RGB or RGBA PNG as an HxWxC uint8 array."""
    data = pathlib.Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    pos, idat = 8, b""
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        tag, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        pos += 12 + n
        if tag == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert depth == 8 and ctype in (2, 6) and interlace == 0
        elif tag == b"IDAT":
            idat += body
    c = 3 if ctype == 2 else 4
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + w * c)
    out = np.zeros((h, w * c), np.int32)
    for y in range(h):
        f, row = raw[y, 0], raw[y, 1:].astype(np.int32)
        up = out[y - 1] if y else np.zeros(w * c, np.int32)
        if f in (0, 2):
            out[y] = (row + (up if f == 2 else 0)) % 256
            continue
        cur = np.zeros(w * c, np.int32)
        for x in range(w * c):
            a = cur[x - c] if x >= c else 0
            b, d = up[x], (up[x - c] if x >= c else 0)
            if f == 1:
                pred = a
            elif f == 3:
                pred = (a + b) // 2
            else:
                p = a + b - d
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - d)
                pred = a if pa <= pb and pa <= pc else b if pb <= pc else d
            cur[x] = (row[x] + pred) % 256
        out[y] = cur
    return out.reshape(h, w, c).astype(np.uint8)


def write_scene(path):
    """A two-triangle garment falling 0.3 m between time codes 0 and 1 above a box collider,
    laid out like clothsr's output: metres, Y up, /World/Garments and /World/Colliders."""
    pytest.importorskip("pxr")
    from pxr import Gf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(1)
    stage.SetTimeCodesPerSecond(30)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    UsdGeom.Scope.Define(stage, "/World/Garments")
    UsdGeom.Scope.Define(stage, "/World/Colliders")
    cloth = UsdGeom.Mesh.Define(stage, "/World/Garments/patch")
    cloth.CreateFaceVertexCountsAttr([3, 3])
    cloth.CreateFaceVertexIndicesAttr([0, 1, 2, 0, 2, 3])
    square = [(-0.3, 0.0, -0.3), (0.3, 0.0, -0.3), (0.3, 0.0, 0.3), (-0.3, 0.0, 0.3)]
    for t, lift in ((0, 0.8), (1, 0.5)):
        pts = [Gf.Vec3f(x, y + lift, z) for x, y, z in square]
        cloth.GetPointsAttr().Set(Vt.Vec3fArray(pts), t)
    box = UsdGeom.Mesh.Define(stage, "/World/Colliders/box")
    corners = [(x, y, z) for x in (-0.2, 0.2) for y in (0.0, 0.4) for z in (-0.2, 0.2)]
    box.CreatePointsAttr([Gf.Vec3f(*p) for p in corners])
    box.CreateFaceVertexCountsAttr([4] * 6)
    box.CreateFaceVertexIndicesAttr(
        [0, 1, 3, 2, 4, 6, 7, 5, 0, 4, 5, 1, 2, 3, 7, 6, 0, 2, 6, 4, 1, 5, 7, 3]
    )
    stage.GetRootLayer().Save()


def render(*args):
    return subprocess.run(
        [BPY, str(RENDER), *map(str, args)], capture_output=True, text=True, timeout=600
    )


def test_renders_the_requested_frames(tmp_path):
    scene = tmp_path / "drop.usda"
    write_scene(scene)
    out = tmp_path / "renders"
    r = render(scene, "--frames", "0,1", "--size", "64x80", "--samples", "4", "-o", out)
    assert r.returncode == 0, r.stdout + r.stderr
    images = {}
    for f in (0, 1):
        png = out / f"drop_f{f}_front.png"
        assert png.exists(), r.stdout + r.stderr
        img = read_png(png)
        assert img.shape[:2] == (80, 64)
        assert img.reshape(-1, img.shape[2]).std(0).max() > 5, "a flat image"
        images[f] = img.astype(int)
    # The garment's time-sampled points are read at each frame: it moved.
    assert np.abs(images[0] - images[1]).max() > 40


def test_user_errors_exit_2_without_a_traceback(tmp_path):
    r = render(tmp_path / "missing.usdc", "-o", tmp_path)
    assert r.returncode == 2 and "no such file" in r.stderr and "Traceback" not in r.stderr
    scene = tmp_path / "drop.usda"
    write_scene(scene)
    r = render(scene, "--frames", "7", "-o", tmp_path)
    assert r.returncode == 2 and "out of range" in r.stderr and "Traceback" not in r.stderr, r.stderr
