#!/usr/bin/env python3
"""Headless product renders of clothsr's USD output (garments on the avatar or colliders), with
Blender as a Python module (Cycles on the CPU), to judge cloth by looking at it.

    .venv-bpy/bin/python tools/render.py OUT.usdc [OUT2.usdc ...] --frames 1,30,60 -o renders/ \
        [--view front|side|back|three-quarter[,...]] [--size 480x600] [--samples 24] [--side-by-side]

`bash .ci/setup` creates .venv-bpy (PyPI bpy). Each input is imported with Blender's USD importer,
whose mesh cache reads the time-sampled points at the scene frame: frame N is time code N. Per
input, frame and view it writes OUT_DIR/<stem>_f<frame>_<view>.png; with --side-by-side and several
inputs also OUT_DIR/<stem1>_vs_<stem2>_f<frame>_<view>.png, the inputs side by side, labelled, all
seen through the same camera. Garments (prims under /World/Garments, or meshes carrying clothsr's
panel ids) get a fabric material, smooth shading and a thin solidified edge; colliders (under
/World/Colliders) a clay material; a shadow catcher under everything and a light grey backdrop.
The camera frames the garments over all the requested frames (--fit all: the colliders too), so
frames of one input share one camera.

Exit status: 0 on success, 2 on a usage or input error (missing file, no mesh, frame out of
range), 1 when Blender fails.
"""

import argparse
import contextlib
import math
import os
import re
import struct
import sys
import tempfile
import time
import zlib

# Where the camera looks from, in Blender's Z-up frame (USD +Z, the avatar's front, is Blender
# -Y): azimuth in degrees from the front, counter-clockwise seen from above.
VIEWS = {"front": 0.0, "three-quarter": 35.0, "side": 90.0, "back": 180.0}
# Garment base colours (linear RGB), one per garment in file order.
PALETTE = [
    (0.03, 0.085, 0.26),  # denim blue
    (0.42, 0.085, 0.05),  # terracotta
    (0.16, 0.22, 0.07),  # olive
    (0.26, 0.08, 0.22),  # plum
    (0.40, 0.30, 0.10),  # ochre
]
SKIN = (0.36, 0.30, 0.26)  # a warm clay mannequin
GREY = (0.33, 0.33, 0.34)  # other colliders: floors, spheres, bars
BACKDROP_TOP = (0.94, 0.94, 0.95)  # display-referred, top to bottom
BACKDROP_BOTTOM = (0.80, 0.81, 0.83)
LABEL_INK = (0.12, 0.12, 0.14)


class UserError(Exception):
    """A usage or input error: reported in one line, exit status 2."""


class BlenderError(Exception):
    """Blender failed: reported with its log's tail, exit status 1."""


def log(msg):
    print(msg, flush=True)


# ---------------------------------------------------------------------------------------------
# Command line


def parse_size(text):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT, e.g. 480x600")
    if not (8 <= w <= 8192 and 8 <= h <= 8192):
        raise argparse.ArgumentTypeError(f"{text!r}: each side must be 8 to 8192 pixels")
    return w, h


def parse_frames(text):
    """'1,30,60', '0-10', 'start', 'end' (mixed): a list of ints and the words start/end."""
    out = []
    for tok in text.split(","):
        tok = tok.strip().lower()
        if tok in ("start", "end", "first", "last"):
            out.append({"first": "start", "last": "end"}.get(tok, tok))
            continue
        m = re.fullmatch(r"(-?\d+)(?:-(-?\d+))?", tok)
        if not m:
            raise argparse.ArgumentTypeError(
                f"{tok!r} is not a frame: use integers, ranges A-B, 'start' or 'end' (e.g. 1,30,60)"
            )
        a = int(m.group(1))
        b = a if m.group(2) is None else int(m.group(2))
        if b < a or b - a > 10000:
            raise argparse.ArgumentTypeError(f"bad frame range {tok!r}")
        out.extend(range(a, b + 1))
    if not out:
        raise argparse.ArgumentTypeError("no frames given")
    return out


def parse_views(text):
    views = []
    for tok in text.split(","):
        tok = tok.strip().lower().replace("_", "-")
        tok = {"3/4": "three-quarter", "threequarter": "three-quarter", "quarter": "three-quarter"}.get(tok, tok)
        if tok not in VIEWS:
            raise argparse.ArgumentTypeError(f"unknown view {tok!r}: choose from {', '.join(VIEWS)}")
        if tok not in views:
            views.append(tok)
    return views


def parse_color(text):
    t = text.strip().lstrip("#")
    if len(t) != 6:
        raise argparse.ArgumentTypeError(f"{text!r} is not a hex colour like 3a5f9e")
    try:
        srgb = [int(t[i : i + 2], 16) / 255.0 for i in (0, 2, 4)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a hex colour like 3a5f9e")
    return tuple(c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in srgb)


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="render.py",
        description="Render frames of clothsr USD output (garments + avatar/colliders) with Blender's Cycles on the CPU.",
    )
    p.add_argument("inputs", nargs="+", metavar="IN.usd", help="clothsr output USD files (.usd, .usda, .usdc)")
    p.add_argument("-o", "--out-dir", required=True, metavar="OUT_DIR", help="folder for the PNGs (created)")
    p.add_argument(
        "--frames",
        type=parse_frames,
        default=["end"],
        help="frames (= USD time codes): 1,30,60, ranges 0-10, 'start', 'end' [default: end]",
    )
    p.add_argument(
        "--view",
        type=parse_views,
        default=["front"],
        help=f"camera: {', '.join(VIEWS)}, or several comma-separated [default: front]",
    )
    p.add_argument("--size", type=parse_size, default=(480, 600), metavar="WxH", help="image size [default: 480x600]")
    p.add_argument("--samples", type=int, default=24, help="Cycles samples per pixel, denoised [default: 24]")
    p.add_argument("--side-by-side", action="store_true", help="with several inputs: also one labelled image per frame and view with the inputs side by side, through the same camera")
    p.add_argument("--labels", help="comma-separated labels of the inputs for --side-by-side [default: file names]")
    p.add_argument(
        "--fit",
        choices=("garments", "all"),
        default="garments",
        help="what the camera frames: the garments (with some of the body around them) or the colliders too [default: garments]",
    )
    p.add_argument("--margin", type=float, default=0.08, help="free border around the framed geometry, as a fraction of the half-frame [default: 0.08]")
    p.add_argument("--elevation", type=float, default=6.0, help="camera elevation in degrees [default: 6]")
    p.add_argument("--lens", type=float, default=60.0, help="focal length in mm (36 mm sensor) [default: 60]")
    p.add_argument("--exposure", type=float, default=-0.5, help="exposure in stops [default: -0.5]")
    p.add_argument("--thickness", type=float, default=1.5, help="rendered cloth thickness in mm (solidify; 0: none) [default: 1.5]")
    p.add_argument("--garment-color", type=parse_color, metavar="RRGGBB", help="sRGB hex colour of every garment [default: a palette]")
    p.add_argument("--no-colliders", action="store_true", help="render the garments alone")
    p.add_argument("--transparent", action="store_true", help="keep the background transparent (RGBA PNG) instead of the grey backdrop")
    p.add_argument("--threads", type=int, default=0, help="render threads (0: all cores) [default: 0]")
    p.add_argument("-v", "--verbose", action="store_true", help="show Blender's own output and per-frame bounds")
    args = p.parse_args(argv)
    if args.samples < 1 or args.samples > 4096:
        p.error("--samples must be 1 to 4096")
    if not 0 <= args.margin < 0.9:
        p.error("--margin must be in [0, 0.9)")
    if not 5 <= args.lens <= 1000:
        p.error("--lens must be 5 to 1000 mm")
    if not 0 <= args.thickness <= 100:
        p.error("--thickness must be 0 to 100 mm")
    if not -10 <= args.exposure <= 10:
        p.error("--exposure must be within -10..10 stops")
    if not -89 <= args.elevation <= 89:
        p.error("--elevation must be within -89..89 degrees")
    if args.labels is not None:
        args.labels = [s.strip() for s in args.labels.split(",")]
        if len(args.labels) != len(args.inputs):
            p.error(f"--labels has {len(args.labels)} labels for {len(args.inputs)} inputs")
    return args


# ---------------------------------------------------------------------------------------------
# PNG output (no packages beyond numpy, which bpy brings)


def write_png(path, img):
    """img: HxWx3 or HxWx4 uint8, top row first."""
    import numpy as np

    h, w, c = img.shape
    rows = np.concatenate([np.zeros((h, 1), np.uint8), img.reshape(h, w * c)], axis=1)

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    data = (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2 if c == 3 else 6, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(rows.tobytes(), 6))
        + chunk(b"IEND", b"")
    )
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def to_u8(img):
    import numpy as np

    return (np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


# ---------------------------------------------------------------------------------------------
# Blender


@contextlib.contextmanager
def captured(verbose):
    """Blender's own stdout/stderr (import timings, render progress) into a buffer; yields a
    callable returning what was captured."""
    if verbose:
        yield lambda: ""
        return
    sys.stdout.flush()
    sys.stderr.flush()
    buf = tempfile.TemporaryFile()
    saved = (os.dup(1), os.dup(2))
    os.dup2(buf.fileno(), 1)
    os.dup2(buf.fileno(), 2)

    def text():
        buf.flush()
        buf.seek(0)
        return buf.read().decode("utf-8", "replace")

    try:
        yield text
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])


def tail(text, n=12):
    lines = [l for l in text.splitlines() if l.strip()]
    return "\n".join("  " + l for l in lines[-n:])


def base_name(obj):
    # Blender suffixes duplicate names with .001; USD prim names cannot hold a dot.
    return obj.name.split(".")[0]


def role_of(obj):
    anc = []
    p = obj.parent
    while p is not None:
        anc.append(base_name(p))
        p = p.parent
    if "Garments" in anc:
        return "garment"
    if "Colliders" in anc:
        return "collider"
    if any(a.name.startswith("clothsr:") for a in obj.data.attributes):
        return "garment"
    return "collider"


class Scene:
    """One input imported into a fresh Blender scene."""

    def __init__(self, bpy, path, verbose, shown=None):
        self.bpy = bpy
        self.path = shown or path  # as the user gave it, for messages
        # An override layer (`run --layer on`) holds only overs: the shot composed with it,
        # written beside it, is what to draw.
        stem, _ = os.path.splitext(path)
        if not stem.endswith(".composed") and os.path.exists(stem + ".composed.usda"):
            path = stem + ".composed.usda"
        bpy.ops.wm.read_factory_settings(use_empty=True)
        with captured(verbose) as out:
            try:
                res = bpy.ops.wm.usd_import(
                    filepath=os.path.abspath(path),
                    import_cameras=False,
                    import_lights=False,
                    import_materials=False,
                    create_world_material=False,
                    import_guide=False,
                    import_proxy=False,
                    read_mesh_colors=False,
                    import_subdivision=False,
                    set_frame_range=True,
                )
            except RuntimeError as e:
                res = {"ERROR": str(e)}
            text = out()
        if res != {"FINISHED"}:
            raise UserError(f"{self.path}: Blender could not import it as USD\n{tail(text) or '  ' + str(res)}")
        sc = bpy.context.scene
        self.meshes = sorted((o for o in sc.objects if o.type == "MESH"), key=lambda o: o.name)
        if not self.meshes:
            raise UserError(
                f"{self.path}: no mesh in the file (clothsr output has its garments as Mesh prims under "
                "/World/Garments; an override layer written with --layer on holds only overs: render "
                "NAME.composed.usda written beside it, or write a standalone stage with --layer off)"
            )
        self.garments = [o for o in self.meshes if role_of(o) == "garment"]
        self.colliders = [o for o in self.meshes if role_of(o) != "garment"]
        if not self.garments:
            print(
                f"warning: {self.path}: no garment (no mesh under /World/Garments): every mesh is rendered as cloth",
                file=sys.stderr,
            )
            self.garments, self.colliders = self.colliders, []
        self.animated = any(
            m.type == "MESH_SEQUENCE_CACHE" for o in self.meshes for m in o.modifiers
        )
        self.start, self.end = sc.frame_start, sc.frame_end

    def resolve_frames(self, tokens):
        frames = []
        for t in tokens:
            f = self.start if t == "start" else self.end if t == "end" else t
            if self.animated and not self.start <= f <= self.end:
                raise UserError(
                    f"{self.path}: frame {f} is out of range: its time samples run from frame "
                    f"{self.start} to {self.end}"
                )
            if f not in frames:
                frames.append(f)
        return frames

    def points(self, objs, frame, limit=40000):
        """World-space vertices of objs at frame (subsampled to about `limit`)."""
        import numpy as np

        bpy = self.bpy
        bpy.context.scene.frame_set(frame)
        dg = bpy.context.evaluated_depsgraph_get()
        out = []
        for o in objs:
            e = o.evaluated_get(dg)
            m = e.to_mesh()
            n = len(m.vertices)
            co = np.empty(n * 3, np.float32)
            m.vertices.foreach_get("co", co)
            e.to_mesh_clear()
            co = co.reshape(n, 3)
            if n > limit:
                co = co[:: int(math.ceil(n / limit))]
            mw = np.array(o.matrix_world, np.float64)
            out.append(co @ mw[:3, :3].T + mw[:3, 3])
        return np.concatenate(out) if out else np.zeros((0, 3))


def huge(pts, ref_extent):
    """A collider much larger than the garments (a floor): kept out of the framing."""
    import numpy as np

    if len(pts) == 0:
        return True
    return float(np.max(pts.max(0) - pts.min(0))) > 4.0 * ref_extent


def material(bpy, name, rgb, cloth):
    m = bpy.data.materials.new(name)
    nodes = m.node_tree.nodes
    bsdf = nodes.get("Principled BSDF")
    inp = bsdf.inputs
    inp["Base Color"].default_value = (*rgb, 1.0)
    if cloth:
        inp["Roughness"].default_value = 0.82
        inp["Specular IOR Level"].default_value = 0.25
        inp["Sheen Weight"].default_value = 0.3
        inp["Sheen Roughness"].default_value = 0.3
        inp["Sheen Tint"].default_value = (0.8, 0.8, 0.8, 1.0)
    else:
        inp["Roughness"].default_value = 0.55
        inp["Specular IOR Level"].default_value = 0.35
    m.diffuse_color = (*rgb, 1.0)
    return m


def look_rotation(direction):
    """Rotation pointing an object's -Z along `direction` with +Y up."""
    from mathutils import Vector

    return Vector(direction).to_track_quat("-Z", "Y").to_euler()


def setup_render(bpy, args):
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    cy = sc.cycles
    cy.device = "CPU"
    cy.samples = args.samples
    cy.use_adaptive_sampling = True
    cy.adaptive_threshold = 0.02
    cy.use_denoising = True
    try:
        cy.denoiser = "OPENIMAGEDENOISE"
        cy.denoising_input_passes = "RGB_ALBEDO_NORMAL"
        cy.denoising_use_gpu = False
    except (TypeError, AttributeError):
        cy.use_denoising = False  # no OpenImageDenoise in this build: noisier, still fine
    cy.max_bounces = 6
    cy.diffuse_bounces = 3
    cy.glossy_bounces = 2
    cy.transmission_bounces = 2
    cy.transparent_max_bounces = 4
    cy.volume_bounces = 0
    cy.caustics_reflective = False
    cy.caustics_refractive = False
    cy.use_auto_tile = False
    r = sc.render
    r.resolution_x, r.resolution_y = args.size
    r.resolution_percentage = 100
    r.film_transparent = True
    r.use_persistent_data = True
    r.threads_mode = "FIXED" if args.threads > 0 else "AUTO"
    if args.threads > 0:
        r.threads = args.threads
    r.image_settings.file_format = "PNG"
    r.image_settings.color_mode = "RGBA"
    r.image_settings.color_depth = "8"
    try:
        sc.view_settings.view_transform = "AgX"
        sc.view_settings.look = "AgX - Medium High Contrast"
    except TypeError:
        pass
    sc.view_settings.exposure = args.exposure


def dress(bpy, scene, args, ground_z, extent):
    """Materials, smoothing, solidify, ground, world."""
    sc = bpy.context.scene
    for i, o in enumerate(scene.garments):
        rgb = args.garment_color or PALETTE[i % len(PALETTE)]
        mat = material(bpy, f"fabric_{i}", rgb, cloth=True)
        o.data.materials.clear()
        o.data.materials.append(mat)
        o.data.shade_smooth()
        if args.thickness > 0:
            sol = o.modifiers.new("cloth_thickness", "SOLIDIFY")
            scale = max(abs(v) for v in o.matrix_world.to_scale()) or 1.0
            sol.thickness = args.thickness * 1e-3 / scale
            sol.offset = 0.0
            # Even offset divides by the angle between faces, and clamped to the edges' length
            # it stays short where cloth folds back on itself: unclamped, a fold of a walked
            # garment threw metre-long shards across the picture.
            sol.use_even_offset = False
            sol.thickness_clamp = 1.0
            sol.use_quality_normals = True
    skin = material(bpy, "clay", SKIN, cloth=False)
    grey = material(bpy, "grey", GREY, cloth=False)
    for o in scene.colliders:
        o.data.materials.clear()
        name = base_name(o).lower()
        avatar = any(k in name for k in ("body", "avatar", "human", "character", "mannequin"))
        o.data.materials.append(skin if avatar or len(o.data.vertices) > 5000 else grey)
        # Smooth, but a box keeps its edges.
        o.data.set_sharp_from_angle(angle=math.radians(50.0))
        if args.no_colliders:
            o.hide_render = True
    # Shadow catcher under everything.
    bpy.ops.mesh.primitive_plane_add(size=60.0 * extent, location=(0.0, 0.0, ground_z))
    ground = bpy.context.active_object
    ground.name = "ground"
    ground.is_shadow_catcher = True
    ground.data.materials.append(grey)
    # Soft, slightly cool ambient light.
    world = bpy.data.worlds.new("studio")
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.62, 0.64, 0.68, 1.0)
    bg.inputs["Strength"].default_value = 0.22
    sc.world = world


def place_camera_and_lights(bpy, view, pts, args, extent):
    """A camera looking at `pts` from `view` that fits them all; three area lights around it."""
    import numpy as np
    from mathutils import Vector

    sc = bpy.context.scene
    w, h = args.size
    az = math.radians(VIEWS[view])
    el = math.radians(args.elevation)
    # From the target towards the camera: front is -Y.
    back = np.array([math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)])
    fwd = -back
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    lo, hi = pts.min(0), pts.max(0)
    c = (lo + hi) / 2.0
    rel = pts - c
    px, py, pz = rel @ right, rel @ up, rel @ fwd
    t_large = 18.0 / args.lens  # 36 mm sensor across the image's larger side
    tx = t_large * (1.0 if w >= h else w / h)
    ty = t_large * (1.0 if h >= w else h / w)
    k = 1.0 - args.margin
    sx = sy = 0.0
    d = extent
    for _ in range(8):
        d = max(
            float(np.max(np.abs(px - sx) / (tx * k) - pz)),
            float(np.max(np.abs(py - sy) / (ty * k) - pz)),
            float(np.max(-pz)) + 0.05 * extent,
        )
        depth = pz + d
        ux, uy = (px - sx) / depth, (py - sy) / depth
        sx += 0.5 * (ux.max() + ux.min()) * d
        sy += 0.5 * (uy.max() + uy.min()) * d
    loc = c + back * d + right * sx + up * sy
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = args.lens
    cam_data.sensor_width = 36.0
    cam_data.sensor_fit = "AUTO"
    cam_data.clip_start = max(1e-3, 0.02 * d)
    cam_data.clip_end = 100.0 * (d + extent)
    cam = bpy.data.objects.new("camera", cam_data)
    sc.collection.objects.link(cam)
    cam.location = Vector(loc)
    cam.rotation_euler = look_rotation(fwd)
    sc.camera = cam

    # Three-point lighting, turning with the camera; power grows with the square of distance so
    # the exposure does not depend on the scene's size.
    target = c + up * sy + right * sx
    R = max(0.5 * extent, 0.05)
    dist = max(4.0 * R, 1.2 * d)
    lights = []
    for name, az_off, elev, power, size in (
        ("key", -45.0, 35.0, 1.0, 0.8),
        ("fill", 55.0, 10.0, 0.25, 2.0),
        ("rim", 160.0, 45.0, 0.5, 2.0),
    ):
        a = az + math.radians(az_off)
        e = math.radians(elev)
        dirv = np.array([math.sin(a) * math.cos(e), -math.cos(a) * math.cos(e), math.sin(e)])
        ld = bpy.data.lights.new(name, "AREA")
        ld.shape = "DISK"
        ld.size = size * R * 2.0
        ld.energy = power * 32.0 * dist * dist
        lo_ = bpy.data.objects.new(name, ld)
        sc.collection.objects.link(lo_)
        lo_.location = Vector(target + dirv * dist)
        lo_.rotation_euler = look_rotation(-dirv)
        lights.append(lo_)
    return [cam, *lights]


def render_rgba(bpy, tmpdir, verbose):
    """Render the scene; the image as float HxWx4 (display-referred, straight alpha), top row first."""
    import numpy as np

    sc = bpy.context.scene
    path = os.path.join(tmpdir, "render.png")
    sc.render.filepath = path
    with captured(verbose) as out:
        try:
            bpy.ops.render.render(write_still=True)
            err = None
        except RuntimeError as e:
            err = str(e)
        text = out()
    if err or not os.path.exists(path):
        raise BlenderError(f"Cycles failed: {err or 'no image written'}\n{tail(text)}")
    img = bpy.data.images.load(path, check_existing=False)
    w, h = img.size
    px = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(px)
    bpy.data.images.remove(img)
    os.remove(path)
    return px.reshape(h, w, 4)[::-1]


def backdrop(h, w):
    import numpy as np

    t = np.linspace(0.0, 1.0, h)[:, None, None]
    top, bottom = np.array(BACKDROP_TOP), np.array(BACKDROP_BOTTOM)
    return np.broadcast_to(top * (1 - t) + bottom * t, (h, w, 3)).astype(np.float32)


def flatten(rgba):
    a = rgba[..., 3:4]
    return rgba[..., :3] * a + backdrop(*rgba.shape[:2]) * (1.0 - a)


def side_by_side(bpy, path, panels, title_suffix):
    """panels: [(label, HxWx3 float)]: one row, a label strip over each."""
    import numpy as np
    import blf
    import imbuf

    h, w = panels[0][1].shape[:2]
    strip = max(14, round(h * 0.055))
    gap = max(2, w // 120)
    W = len(panels) * w + (len(panels) - 1) * gap
    H = h + strip
    out = np.empty((H, W, 3), np.float32)
    out[:] = np.array(BACKDROP_TOP, np.float32)
    for i, (_, img) in enumerate(panels):
        x = i * (w + gap)
        out[strip:, x : x + w] = img
        if i:
            out[:, x - gap : x] = np.array(BACKDROP_BOTTOM, np.float32) * 0.85
    write_png(path, to_u8(out))
    ib = imbuf.load(path)
    font = 0
    size = max(8, round(strip * 0.6))
    with blf.bind_imbuf(font, ib):
        blf.size(font, size)
        blf.color(font, *LABEL_INK, 1.0)
        for i, (label, _) in enumerate(panels):
            text = f"{label}  {title_suffix}"
            tw, th = blf.dimensions(font, text)
            while tw > w - 8 and len(text) > 4:
                text = text[: len(text) - 5] + "…"
                tw, th = blf.dimensions(font, text)
            x = i * (w + gap) + max(4, (w - tw) / 2)
            # imbuf rows run bottom-up: the strip is at the top.
            y = H - strip + (strip - size * 0.72) / 2
            blf.position(font, x, y, 0)
            blf.draw_buffer(font, text)
    imbuf.write(ib, filepath=path)


def unique_stems(paths):
    base = [os.path.splitext(os.path.basename(p))[0] for p in paths]
    stems = list(base)
    for i, s in enumerate(base):
        if base.count(s) > 1:
            parent = os.path.basename(os.path.dirname(os.path.abspath(paths[i])))
            stems[i] = f"{parent}_{s}" if parent else s
    # Still clashing (same folder name): number them.
    seen = {}
    dup = [stems.count(s) > 1 for s in stems]
    for i, s in enumerate(stems):
        if dup[i]:
            seen[s] = seen.get(s, 0) + 1
            stems[i] = f"{s}_{seen[s]}"
    return stems


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    for p in args.inputs:
        if not os.path.exists(p):
            raise UserError(f"{p}: no such file")
        if os.path.isdir(p):
            raise UserError(f"{p}: is a folder, not a USD file")
        if os.path.splitext(p)[1].lower() not in (".usd", ".usda", ".usdc", ".usdz"):
            raise UserError(f"{p}: not a USD file (.usd, .usda, .usdc or .usdz)")
    try:
        import bpy  # noqa: F401
        import numpy as np
    except ImportError as e:
        raise UserError(
            f"cannot import bpy ({e}): run this with Blender's Python module, e.g. "
            ".venv-bpy/bin/python tools/render.py (bash .ci/setup creates .venv-bpy)"
        )
    inputs = list(args.inputs)
    stems = unique_stems(args.inputs)
    labels = args.labels or stems
    sbs = args.side_by_side and len(inputs) > 1
    if args.side_by_side and len(inputs) == 1:
        print("warning: --side-by-side needs several inputs: writing the single images only", file=sys.stderr)

    # Pass 1: import every input (checking them all before rendering anything) and gather the
    # geometry the camera frames at each requested frame.
    plans = []
    for path in inputs:
        scene = Scene(bpy, path, args.verbose)
        frames = scene.resolve_frames(args.frames)
        g_pts, c_pts, lows = [], [], []
        for f in frames:
            g = scene.points(scene.garments, f)
            if len(g) == 0:
                raise UserError(f"{path}: the garments have no vertices at frame {f}")
            if not np.isfinite(g).all():
                raise UserError(f"{path}: the garments have non-finite points at frame {f}")
            g_pts.append(g)
            cs = [scene.points([o], f) for o in scene.colliders]
            c_pts.append(cs)
            lows.append(min([float(g[:, 2].min())] + [float(c[:, 2].min()) for c in cs if len(c)]))
            if args.verbose:
                log(f"{os.path.basename(path)} frame {f}: garments from {np.round(g.min(0), 4)} to {np.round(g.max(0), 4)}")
        gall = np.concatenate(g_pts)
        g_extent = float(np.max(gall.max(0) - gall.min(0)))
        fit = [gall]
        if args.fit == "all" and not args.no_colliders:
            for cs in c_pts:
                fit += [c for c in cs if not huge(c, g_extent)]
        fit = np.concatenate(fit)
        plans.append(
            dict(
                path=path,
                frames=frames,
                fit=fit,
                ground=min(lows) - 1e-4,
            )
        )
        rng = f"frames {scene.start}..{scene.end}" if scene.animated else "static"
        log(
            f"{os.path.basename(path)}: {len(scene.garments)} garment(s) "
            f"({', '.join(base_name(o) for o in scene.garments)}), {len(scene.colliders)} collider(s), {rng}"
        )
    if sbs:
        shared = np.concatenate([p["fit"] for p in plans])
        ground = min(p["ground"] for p in plans)
        for p in plans:
            p["fit"], p["ground"] = shared, ground

    try:
        os.makedirs(args.out_dir, exist_ok=True)
    except OSError as e:
        raise UserError(f"cannot create the output folder {args.out_dir}: {e.strerror or e}")

    # Pass 2: render.
    panels = {}  # (frame, view) -> [(label, image)]
    t_all = time.time()
    n_images = 0
    with tempfile.TemporaryDirectory(prefix="clothsr-render-") as tmpdir:
        for i, plan in enumerate(plans):
            scene = Scene(bpy, plan["path"], args.verbose)
            fit = plan["fit"]
            extent = float(np.max(fit.max(0) - fit.min(0))) or 1.0
            with captured(args.verbose):
                setup_render(bpy, args)
            dress(bpy, scene, args, plan["ground"], extent)
            for view in args.view:
                rig = place_camera_and_lights(bpy, view, fit, args, extent)
                for f in plan["frames"]:
                    t0 = time.time()
                    bpy.context.scene.frame_set(f)
                    rgba = render_rgba(bpy, tmpdir, args.verbose)
                    img = flatten(rgba)
                    out = os.path.join(args.out_dir, f"{stems[i]}_f{f}_{view}.png")
                    if args.transparent:
                        write_png(out, to_u8(rgba))
                    else:
                        write_png(out, to_u8(img))
                    n_images += 1
                    log(f"wrote {out} ({time.time() - t0:.1f} s)")
                    if sbs:
                        panels.setdefault((f, view), []).append((labels[i], img))
                for o in rig:
                    data = o.data
                    bpy.data.objects.remove(o)
                    if isinstance(data, bpy.types.Camera):
                        bpy.data.cameras.remove(data)
                    else:
                        bpy.data.lights.remove(data)
        if sbs:
            name = "_vs_".join(stems)
            if len(name) > 120:
                name = "side_by_side"
            for (f, view), ps in panels.items():
                if len(ps) < 2:
                    continue  # a frame only some inputs have (each input checked its own range)
                out = os.path.join(args.out_dir, f"{name}_f{f}_{view}.png")
                side_by_side(bpy, out, ps, f"frame {f}")
                log(f"wrote {out}")
    log(f"{n_images} image(s) in {time.time() - t_all:.1f} s")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except UserError as e:
        print(f"render.py: error: {e}", file=sys.stderr)
        sys.exit(2)
    except BlenderError as e:
        print(f"render.py: error: {e}", file=sys.stderr)
        sys.exit(1)
    except OSError as e:  # writing the images
        print(f"render.py: error: {e}", file=sys.stderr)
        sys.exit(1)
    except KeyboardInterrupt:
        print("render.py: interrupted", file=sys.stderr)
        sys.exit(130)
