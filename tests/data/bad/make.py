"""(Re)generates the bad-input corpus in tests/data/bad/: broken and borderline USD stages, OBJ
meshes, GarmentCode patterns and models folders, each with its expected outcome in
expected.json (written by hand, not by this script).

Run from the repository root with the project's venv (it imports pxr for the binary stages):

    .venv/bin/python tests/data/bad/make.py

Everything is deterministic (fixed seeds, no time stamps), so regenerating leaves git clean.
Every file stays small (< 50 KB each, < 1 MB in all); the script checks it.
"""
import json
import math
import pathlib
import random
import shutil
import struct

from pxr import Sdf

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[2]
GENERIC_ISR = ROOT / "models" / "generic" / "isr"
# What this script owns in HERE (removed and rewritten on every run); README.md, expected.json
# and make.py itself are kept.
OWNED = ("usd", "obj", "pattern", "models", "misc")
MAX_FILE = 50 * 1024
MAX_TOTAL = 1024 * 1024


def write(rel: str, data) -> pathlib.Path:
    path = HERE / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    path.write_bytes(data)
    return path


# --------------------------------------------------------------------------------------------
# USD (text stages written by hand, so every file reads as what it tests)
# --------------------------------------------------------------------------------------------


def fmt(x: float) -> str:
    if isinstance(x, str):
        return x
    if math.isnan(x):
        return "nan"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if abs(x) >= 1e6:
        return repr(float(x))
    return repr(float(round(x, 6))) if x != int(x) else str(int(x))


def vec(v) -> str:
    return "(" + ", ".join(fmt(c) for c in v) + ")"


def arr(items, f=vec) -> str:
    return "[" + ", ".join(f(i) for i in items) + "]"


def ints(items) -> str:
    return "[" + ", ".join(str(i) for i in items) + "]"


def stage_header(mpu=1, up="Y", extra="", schema=1, end=30) -> str:
    lines = ["#usda 1.0", "("]
    if schema is not None:
        lines += ["    customLayerData = {", f'        int "clothsr:schemaVersion" = {schema}', "    }"]
    lines += [
        '    defaultPrim = "World"',
        f"    endTimeCode = {end}",
        "    framesPerSecond = 30",
    ]
    if mpu is not None:
        lines.append(f"    metersPerUnit = {mpu}")
    lines += ["    startTimeCode = 0", "    timeCodesPerSecond = 30"]
    if up is not None:
        lines.append(f'    upAxis = "{up}"')
    if extra:
        lines.append(extra)
    lines.append(")")
    return "\n".join(lines) + "\n\n"


def grid(n=4, size=0.3, y=0.5):
    """An n x n vertex sheet in the xz plane at height y: points, st (metres), quads."""
    pts, st = [], []
    for j in range(n):
        for i in range(n):
            x, z = size * i / (n - 1) - size / 2, size * j / (n - 1) - size / 2
            pts.append([x, y, z])
            st.append([x + size / 2, z + size / 2])
    quads = []
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            quads.append([a, a + n, a + n + 1, a + 1])
    return pts, st, quads


def tris_of(quads):
    out = []
    for a, b, c, d in quads:
        out += [[a, b, c], [a, c, d]]
    return out


def mesh_prim(
    name,
    faces,
    pts,
    st=None,
    st_interp="vertex",
    cloth=True,
    indent="    ",
    counts=None,
    indices=None,
    points_attr=None,
) -> str:
    api = ' (\n' + indent + '    prepend apiSchemas = ["ClothsrGarmentAPI"]\n' + indent + ")" if cloth else ""
    body = []
    counts = [len(f) for f in faces] if counts is None else counts
    indices = [i for f in faces for i in f] if indices is None else indices
    body.append(f"int[] faceVertexCounts = {ints(counts)}")
    body.append(f"int[] faceVertexIndices = {ints(indices)}")
    if points_attr is not None:
        body.append(points_attr)
    elif pts is not None:
        body.append(f"point3f[] points = {arr(pts)}")
    if st is not None:
        body.append(
            f"texCoord2f[] primvars:st = {arr(st)} (\n{indent}        interpolation = \"{st_interp}\"\n{indent}    )"
        )
    body.append('uniform token subdivisionScheme = "none"')
    inner = "".join(f"{indent}    {line}\n" for line in body)
    return f'{indent}def Mesh "{name}"{api}\n{indent}{{\n{inner}{indent}}}\n'


def world(*children) -> str:
    return 'def Xform "World"\n{\n' + "\n".join(children) + "}\n"


def cloth_stage(faces, pts, st, name="Sheet", header=None, **kw) -> str:
    return (header or stage_header()) + world(mesh_prim(name, faces, pts, st, **kw))


def box(lo, hi):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    pts = [
        [x0, y0, z0], [x1, y0, z0], [x0, y1, z0], [x1, y1, z0],
        [x0, y0, z1], [x1, y0, z1], [x0, y1, z1], [x1, y1, z1],
    ]
    tris = [
        [0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
        [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5],
    ]
    return pts, tris


def collider_prim(name, lo, hi, indent="    ") -> str:
    pts, tris = box(lo, hi)
    return (
        f'{indent}def Mesh "{name}" (\n{indent}    prepend apiSchemas = ["PhysicsCollisionAPI"]\n{indent})\n'
        f"{indent}{{\n"
        f"{indent}    int[] faceVertexCounts = {ints([3] * len(tris))}\n"
        f"{indent}    int[] faceVertexIndices = {ints([i for t in tris for i in t])}\n"
        f"{indent}    point3f[] points = {arr(pts)}\n"
        f'{indent}    uniform token subdivisionScheme = "none"\n'
        f"{indent}}}\n"
    )


def hexagon_disc(rings=2, r=0.05, y=0.5):
    """A disc: a central hexagon and `rings` rings of quads around it (all convex)."""
    pts = []
    for k in range(rings + 1):
        rad = r * (k + 1)
        for i in range(6):
            a = math.pi / 3 * i
            pts.append([rad * math.cos(a), y, rad * math.sin(a)])
    # Wound consistently: each shared edge is walked one way by one face, the other way by the
    # other.
    faces = [[5, 4, 3, 2, 1, 0]]
    for k in range(rings):
        for i in range(6):
            a, b = 6 * k + i, 6 * k + (i + 1) % 6
            faces.append([a, b, b + 6, a + 6])
    st = [[p[0] + 0.2, p[2] + 0.2] for p in pts]
    return pts, st, faces


def make_usd():
    pts, st, quads = grid()
    tris = tris_of(quads)

    write("usd/not_usd.usda", "This is a shopping list, not a USD stage.\n- milk\n- thread\n")
    rng = random.Random(1234)
    write("usd/random_bytes.usdc", bytes(rng.randrange(256) for _ in range(4096)))
    # A real binary stage, cut in half.
    full = HERE / "usd" / "_full.usdc"
    full.parent.mkdir(parents=True, exist_ok=True)
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.ImportFromString(cloth_stage(tris, pts, st))
    layer.Export(str(full))
    data = full.read_bytes()
    full.unlink()
    write("usd/truncated.usdc", data[: len(data) // 2])
    write("usd/empty_stage.usda", stage_header() + "")

    bad = [list(p) for p in pts]
    bad[5][1] = float("nan")
    write("usd/nan_points.usda", cloth_stage(tris, bad, st))
    bad = [list(p) for p in pts]
    bad[6][0] = float("inf")
    write("usd/inf_points.usda", cloth_stage(tris, bad, st))
    bad = [list(p) for p in pts]
    bad[9][2] = 1e30
    write("usd/huge_points.usda", cloth_stage(tris, bad, st))
    write("usd/empty_mesh.usda", stage_header() + world(mesh_prim("Sheet", [], [], counts=[], indices=[])))
    bad = [i for t in tris for i in t]
    bad[7] = 16
    write("usd/face_index_out_of_range.usda", cloth_stage(tris, pts, st, indices=bad))
    write(
        "usd/face_counts_mismatch.usda",
        cloth_stage(tris, pts, st, counts=[3] * (len(tris) + 2)),
    )
    two = [list(t) for t in tris]
    two[4] = two[4][:2]
    write("usd/two_vertex_face.usda", cloth_stage(two, pts, st))
    deg = [list(t) for t in tris] + [[5, 6, 6]]
    write("usd/degenerate_face.usda", cloth_stage(deg, pts, st))
    write("usd/quads.usda", cloth_stage(quads, pts, st))
    hp, hs, hf = hexagon_disc()
    write("usd/ngons.usda", cloth_stage(hf, hp, hs))
    # One 12-gon: the outline of the 4 x 4 grid, four corners and eight points along its sides.
    # Fan triangulation from its first corner gives zero-area triangles (collinear corners).
    outline = [0, 1, 2, 3, 7, 11, 15, 14, 13, 12, 8, 4]
    write(
        "usd/ngon_collinear.usda",
        cloth_stage([list(range(12))], [pts[i] for i in outline], [st[i] for i in outline]),
    )
    # An L-shaped (concave) hexagon, fan-split from its reflex corner.
    lp = [[0.2, 0.5, 0.1], [0.1, 0.5, 0.1], [0.1, 0.5, 0.2], [0.0, 0.5, 0.2], [0.0, 0.5, 0.0], [0.2, 0.5, 0.0]]
    ls = [[p[0], p[2]] for p in lp]
    write("usd/ngon_concave.usda", cloth_stage([[0, 1, 2, 3, 4, 5][::-1]], lp, ls))
    # Non-manifold: a fin, a third triangle on the edge (5, 6), its own st chart beside the sheet.
    nm_pts = [list(p) for p in pts] + [[0.0, 0.6, -0.05]]
    nm_st = [list(s) for s in st] + [[0.45, 0.15]]
    # The fin's corner shares points 5 and 6 but has its own st: faceVarying st.
    nm_faces = [list(t) for t in tris]
    nm_faces.append([5, 6, 16])
    corner_st = [st[i] for t in tris for i in t] + [[0.4, 0.1], [0.5, 0.1], [0.45, 0.2]]
    write("usd/non_manifold.usda", cloth_stage(nm_faces, nm_pts, corner_st, st_interp="faceVarying"))
    flipped = [list(t) for t in tris]
    flipped[7] = flipped[7][::-1]
    write("usd/flipped_face.usda", cloth_stage(flipped, pts, st))
    dup = [list(t) for t in tris] + [list(tris[3])]
    write("usd/duplicated_face.usda", cloth_stage(dup, pts, st))
    # Time samples whose point count changes: 16 points at 0, 15 at 1.
    samples = (
        "point3f[] points.timeSamples = {\n"
        f"            0: {arr(pts)},\n"
        f"            1: {arr(pts[:-1])},\n"
        "        }"
    )
    write("usd/point_count_changes.usda", cloth_stage(tris, None, st, points_attr=samples))
    write("usd/st_too_few.usda", cloth_stage(tris, pts, st[:-3]))
    write("usd/st_uniform.usda", cloth_stage(tris, pts, st[: len(tris)], st_interp="uniform"))
    bad = [list(s) for s in st]
    bad[3][0] = float("nan")
    write("usd/st_nan.usda", cloth_stage(tris, pts, bad))
    write("usd/no_meters_per_unit.usda", cloth_stage(tris, pts, st, header=stage_header(mpu=None)))
    # Z up, centimetres: a 30 cm sheet 50 cm up, over a box. x, y, z(up) in cm.
    zp = [[p[0] * 100, -p[2] * 100, p[1] * 100] for p in pts]
    zs = [[s[0], s[1]] for s in st]
    write(
        "usd/zup_centimetres.usda",
        stage_header(mpu=0.01, up="Z")
        + world(mesh_prim("Sheet", tris, zp, zs), collider_prim("Table", [-20, -20, 0], [20, 20, 40])),
    )
    ref = stage_header() + world(
        mesh_prim("Sheet", tris, pts, st),
        '    def Xform "Props" (\n        prepend references = @./no_such_props.usda@\n    )\n    {\n    }\n',
    )
    write("usd/missing_reference.usda", ref)
    write(
        "usd/missing_sublayer.usda",
        stage_header(extra="    subLayers = [\n        @./no_such_sublayer.usda@\n    ]")
        + world(mesh_prim("Sheet", tris, pts, st)),
    )
    write("usd/future_schema.usda", cloth_stage(tris, pts, st, header=stage_header(schema=99)))
    write("usd/panel_missing_vertices.usda", panel_stage(missing_vertices=True))
    write("usd/scaled_panel.usda", panel_stage(scale=2.0))
    write("usd/avatar_no_animation.usda", avatar_stage())
    write("usd/avatar_bad_joint_indices.usda", avatar_stage(joint_index=7))
    write("usd/avatar_skeleton_missing.usda", avatar_stage(skeleton="/World/Avatar/NoSuchSkeleton"))


def panel_stage(missing_vertices=False, scale=None) -> str:
    """A pattern garment (one square ClothsrPanel) as clothsr writes it."""
    verts = "" if missing_vertices else "                double2[] clothsr:vertices = [(0, 0), (0.3, 0), (0.3, 0.3), (0, 0.3)]\n"
    ops = '["xformOp:translate", "xformOp:rotateXYZ"]'
    scale_op = ""
    if scale is not None:
        scale_op = f"                double3 xformOp:scale = ({scale}, {scale}, {scale})\n"
        ops = '["xformOp:translate", "xformOp:rotateXYZ", "xformOp:scale"]'
    return stage_header() + (
        'def Xform "World"\n{\n'
        '    def Scope "Garments"\n    {\n'
        '        def Xform "square" (\n            prepend apiSchemas = ["ClothsrGarmentAPI"]\n        )\n        {\n'
        '            string clothsr:fabric:name = "cotton"\n'
        '            def ClothsrPanel "front"\n            {\n'
        "                double4[] clothsr:edgeCurveParams = [(0, 0, 0, 0), (0, 0, 0, 0), (0, 0, 0, 0), (0, 0, 0, 0)]\n"
        '                token[] clothsr:edgeCurveTypes = ["straight", "straight", "straight", "straight"]\n'
        "                int2[] clothsr:edgeEndpoints = [(0, 1), (1, 2), (2, 3), (3, 0)]\n"
        f"{verts}"
        "                double3 xformOp:rotateXYZ = (-90, 0, 0)\n"
        "                double3 xformOp:translate = (-0.15, 0.5, 0.15)\n"
        f"{scale_op}"
        f"                uniform token[] xformOpOrder = {ops}\n"
        "            }\n        }\n    }\n}\n"
    )


def avatar_stage(joint_index=None, skeleton="/World/Avatar/Skel") -> str:
    """A cloth sheet over a UsdSkel avatar: a box skinned to a two-joint skeleton, no animation
    (rest pose). `joint_index` replaces the box's joint indices; `skeleton` its skel:skeleton."""
    pts, st, quads = grid(y=0.6)
    bpts, btris = box([-0.15, 0.0, -0.15], [0.15, 0.5, 0.15])
    n = len(bpts)
    ji = [0 if p[1] < 0.25 else 1 for p in bpts]
    if joint_index is not None:
        ji = [joint_index] * n
    ident = "((1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1))"
    hip = "((1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0.25, 0, 1))"
    hip_local = hip
    avatar = (
        '    def SkelRoot "Avatar" (\n        prepend apiSchemas = ["SkelBindingAPI"]\n    )\n    {\n'
        '        def Skeleton "Skel" (\n            prepend apiSchemas = ["SkelBindingAPI"]\n        )\n        {\n'
        f"            uniform matrix4d[] bindTransforms = [{ident}, {hip}]\n"
        '            uniform token[] joints = ["root", "root/hip"]\n'
        f"            uniform matrix4d[] restTransforms = [{ident}, {hip_local}]\n"
        "        }\n\n"
        '        def Mesh "Body" (\n            prepend apiSchemas = ["SkelBindingAPI"]\n        )\n        {\n'
        f"            int[] faceVertexCounts = {ints([3] * len(btris))}\n"
        f"            int[] faceVertexIndices = {ints([i for t in btris for i in t])}\n"
        f"            point3f[] points = {arr(bpts)}\n"
        f"            matrix4d primvars:skel:geomBindTransform = {ident}\n"
        f"            int[] primvars:skel:jointIndices = {ints(ji)} (\n"
        '                elementSize = 1\n                interpolation = "vertex"\n            )\n'
        f"            float[] primvars:skel:jointWeights = {ints([1] * n)} (\n"
        '                elementSize = 1\n                interpolation = "vertex"\n            )\n'
        f"            rel skel:skeleton = <{skeleton}>\n"
        '            uniform token subdivisionScheme = "none"\n'
        "        }\n    }\n"
    )
    return stage_header() + world(mesh_prim("Sheet", tris_of(quads), pts, st), avatar)


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------


def obj_grid(n=4, size=0.3, y=0.5, vt=True, quads=False):
    pts, st, qs = grid(n, size, y)
    lines = ["# clothsr bad-input corpus"]
    lines += [f"v {fmt(p[0])} {fmt(p[1])} {fmt(p[2])}" for p in pts]
    if vt:
        lines += [f"vt {fmt(s[0])} {fmt(s[1])}" for s in st]
    faces = qs if quads else tris_of(qs)
    for f in faces:
        if vt:
            lines.append("f " + " ".join(f"{i + 1}/{i + 1}" for i in f))
        else:
            lines.append("f " + " ".join(str(i + 1) for i in f))
    return lines


def make_obj():
    write("obj/bad_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 7/3\n")
    write(
        "obj/negative_index.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf -1/-1 -2/-2 -9/-3\n",
    )
    write("obj/no_vt.obj", "\n".join(obj_grid(vt=False)) + "\n")
    write("obj/quads.obj", "\n".join(obj_grid(quads=True)) + "\n")
    hp, hs, hf = hexagon_disc()
    lines = ["# a hexagon ringed by quads"]
    lines += [f"v {fmt(p[0])} {fmt(p[1])} {fmt(p[2])}" for p in hp]
    lines += [f"vt {fmt(s[0])} {fmt(s[1])}" for s in hs]
    lines += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in f) for f in hf]
    write("obj/ngons.obj", "\n".join(lines) + "\n")
    write("obj/nan_vertex.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    write("obj/huge_index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4294967295\n")
    write("obj/empty.obj", "")
    write("obj/garbage.obj", "<html><body>404 Not Found</body></html>\n\x00\x01 not an OBJ\n")
    write("obj/collinear.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")


# --------------------------------------------------------------------------------------------
# GarmentCode JSON (the valid two-panel pattern of tests/bad_input.rs, broken one way each)
# --------------------------------------------------------------------------------------------


def pattern():
    return {
        "pattern": {
            "panels": {
                "front": {
                    "translation": [0, 100, 15],
                    "rotation": [0, 0, 0],
                    "vertices": [[-30, -50], [30, -50], [18, 0], [-18, 0]],
                    "edges": [
                        {"endpoints": [0, 1], "curvature": {"type": "quadratic", "params": [[0.5, -0.1]]}},
                        {"endpoints": [1, 2]},
                        {"endpoints": [2, 3], "curvature": {"type": "circle", "params": [60, 0, 1]}},
                        {"endpoints": [3, 0]},
                    ],
                },
                "back": {
                    "translation": [0, 100, -15],
                    "rotation": [0, 180, 0],
                    "vertices": [[-30, -50], [30, -50], [18, 0], [-18, 0]],
                    "edges": [
                        {"endpoints": [0, 1]},
                        {"endpoints": [1, 2]},
                        {"endpoints": [2, 3]},
                        {"endpoints": [3, 0]},
                    ],
                },
            },
            "stitches": [
                [{"panel": "front", "edge": 1}, {"panel": "back", "edge": 3}],
                [{"panel": "front", "edge": 3}, {"panel": "back", "edge": 1}],
            ],
        },
        "properties": {"units_in_meter": 100, "curvature_coords": "relative"},
    }


def write_pattern(rel, edit):
    p = pattern()
    edit(p)
    write(rel, json.dumps(p, indent=1, sort_keys=True) + "\n")


def make_patterns():
    panels = lambda p: p["pattern"]["panels"]  # noqa: E731

    write_pattern("pattern/valid.json", lambda p: None)

    def bowtie(p):
        panels(p)["back"]["vertices"] = [[-30, -50], [30, -50], [-18, 0], [18, 0]]

    write_pattern("pattern/self_intersecting.json", bowtie)

    def flat(p):
        panels(p)["back"]["vertices"] = [[-30, 0], [30, 0], [18, 0], [-18, 0]]

    write_pattern("pattern/zero_area.json", flat)

    def huge_quadratic(p):
        panels(p)["front"]["edges"][0]["curvature"]["params"] = [[0.5, 400.0]]

    write_pattern("pattern/quadratic_huge.json", huge_quadratic)

    def small_circle(p):
        # The chord of front edge 2 is 36 cm; a 5 cm radius cannot span it.
        panels(p)["front"]["edges"][2]["curvature"]["params"] = [5, 0, 1]

    write_pattern("pattern/circle_radius_too_small.json", small_circle)

    def rounded_circle(p):
        # 17.99 cm for a 36 cm chord: short of half the chord by rounding only, which SVG (and
        # clothsr) take as the half circle.
        panels(p)["front"]["edges"][2]["curvature"]["params"] = [17.99, 0, 1]

    write_pattern("pattern/circle_radius_rounding.json", rounded_circle)

    def missing_edge(p):
        p["pattern"]["stitches"][0][1]["edge"] = 9

    write_pattern("pattern/stitch_missing_edge.json", missing_edge)

    def missing_panel(p):
        p["pattern"]["stitches"][1][0]["panel"] = "sleeve"

    write_pattern("pattern/stitch_missing_panel.json", missing_panel)

    def seam_lengths(p):
        panels(p)["back"]["vertices"] = [[-30, -50], [30, -50], [18, -45], [-18, -45]]

    write_pattern("pattern/seam_lengths_differ.json", seam_lengths)

    def negative_units(p):
        p["properties"]["units_in_meter"] = -100

    write_pattern("pattern/negative_units.json", negative_units)

    def unknown_units(p):
        p["properties"]["units_in_meter"] = "furlongs"

    write_pattern("pattern/unknown_units.json", unknown_units)
    write("pattern/not_json.json", '{"pattern": {"panels": {"front": [1, 2,\n')

    def no_panels(p):
        p["pattern"]["panels"] = {}
        p["pattern"]["stitches"] = []

    write_pattern("pattern/no_panels.json", no_panels)


# --------------------------------------------------------------------------------------------
# Models folders (for `clothsr run --models DIR`)
# --------------------------------------------------------------------------------------------


class Cbor:
    """The little of CBOR (RFC 8949) that burnpack metadata uses: unsigned ints, text and byte
    strings, arrays and maps."""

    @staticmethod
    def decode(buf: bytes, pos: int = 0):
        head = buf[pos]
        major, info = head >> 5, head & 31
        pos += 1
        if info < 24:
            arg = info
        elif info in (24, 25, 26, 27):
            size = 1 << (info - 24)
            arg = int.from_bytes(buf[pos : pos + size], "big")
            pos += size
        else:
            raise ValueError(f"CBOR item {head:#x} not supported")
        if major == 0:
            return arg, pos
        if major == 2:
            return bytes(buf[pos : pos + arg]), pos + arg
        if major == 3:
            return buf[pos : pos + arg].decode(), pos + arg
        if major == 4:
            out = []
            for _ in range(arg):
                item, pos = Cbor.decode(buf, pos)
                out.append(item)
            return out, pos
        if major == 5:
            out = {}
            for _ in range(arg):
                key, pos = Cbor.decode(buf, pos)
                out[key], pos = Cbor.decode(buf, pos)
            return out, pos
        raise ValueError(f"CBOR major type {major} not supported")

    @staticmethod
    def _head(major: int, arg: int) -> bytes:
        if arg < 24:
            return bytes([major << 5 | arg])
        for info, size in ((24, 1), (25, 2), (26, 4), (27, 8)):
            if arg < 1 << (8 * size):
                return bytes([major << 5 | info]) + arg.to_bytes(size, "big")
        raise ValueError("too large")

    @staticmethod
    def encode(v) -> bytes:
        if isinstance(v, bool):
            raise ValueError("bool not supported")
        if isinstance(v, int):
            return Cbor._head(0, v)
        if isinstance(v, bytes):
            return Cbor._head(2, len(v)) + v
        if isinstance(v, str):
            b = v.encode()
            return Cbor._head(3, len(b)) + b
        if isinstance(v, (list, tuple)):
            return Cbor._head(4, len(v)) + b"".join(Cbor.encode(x) for x in v)
        if isinstance(v, dict):
            return Cbor._head(5, len(v)) + b"".join(Cbor.encode(k) + Cbor.encode(x) for k, x in v.items())
        raise ValueError(f"{type(v)} not supported")


def burnpack_metadata(data: bytes) -> dict:
    magic, version, size = struct.unpack("<IHI", data[:10])
    assert magic == 0x4255524E and version == 1, "not a burnpack file"
    meta, _ = Cbor.decode(data[10 : 10 + size])
    return meta


def burnpack(tensors) -> bytes:
    """A burnpack file of `tensors`: [(name, shape, param_id, float32 values)]."""
    descriptors, chunks, offset = {}, [], 0
    for name, shape, param_id, values in tensors:
        raw = struct.pack(f"<{len(values)}f", *values)
        descriptors[name] = {
            "dtype": "F32",
            "shape": list(shape),
            "data_offsets": [offset, offset + len(raw)],
            "param_id": param_id,
        }
        pad = (-len(raw)) % 256
        chunks.append(raw + b"\0" * pad)
        offset += len(raw) + pad
    meta = Cbor.encode({"tensors": descriptors})
    header = struct.pack("<IHI", 0x4255524E, 1, len(meta))
    start = -(-(len(header) + len(meta)) // 256) * 256
    return header + meta + b"\0" * (start - len(header) - len(meta)) + b"".join(chunks)


def tiny_isr(embed_dim=2, heads=1, mlp_ratio=2.0):
    """A complete ISR model far smaller than the generic one: the generic config with a network
    of one Swin block of `embed_dim` channels, and all-zero weights of exactly its shapes (the
    tensor names and layouts of the generic model.bpk). It runs, adding no detail."""
    config = json.loads((GENERIC_ISR / "config.json").read_text())
    config["model"].update(embed_dim=embed_dim, depths=[1], heads=heads, mlp_ratio=mlp_ratio)
    generic = burnpack_metadata((GENERIC_ISR / "model.bpk").read_bytes())["tensors"]
    old_c = 32
    c, hidden = embed_dim, int(embed_dim * mlp_ratio)
    old_hidden = 64
    tensors = []
    for pid, name in enumerate(sorted(generic), start=1):
        if name.startswith("layers.") and not name.startswith("layers.0."):
            continue
        if name.startswith("layers.0.layers.") and not name.startswith("layers.0.layers.0."):
            continue
        old = generic[name]["shape"]
        if name.endswith("bias_table"):
            shape = [old[0], heads]
        else:
            shape = [
                c if d == old_c else hidden if d == old_hidden else 3 * c if d == 3 * old_c else d
                for d in old
            ]
        count = 1
        for d in shape:
            count *= d
        tensors.append((name, shape, pid, [0.0] * count))
    return config, burnpack(tensors)


def make_models():
    config = json.loads((GENERIC_ISR / "config.json").read_text())
    truncated = (GENERIC_ISR / "model.bpk").read_bytes()[:4096]
    tiny_config, tiny_weights = tiny_isr()

    def isr(folder, cfg, weights):
        if cfg is not None:
            text = cfg if isinstance(cfg, str) else json.dumps(cfg, indent=2) + "\n"
            write(f"models/{folder}/isr/config.json", text)
        write(f"models/{folder}/isr/model.bpk", weights)

    # The control: a complete (tiny) models folder, which runs.
    isr("tiny_valid", tiny_config, tiny_weights)
    # No isr/config.json: only weights.
    isr("no_isr_config", None, tiny_weights)
    # A config from another (imagined) version: the network under another key, sizes renamed.
    old = {
        "version": 0,
        "network": {"channels": 2, "blocks": [1], "heads": 1, "window": 8},
        "pixel_size_m": 0.0025,
        "patch": 32,
    }
    isr("config_other_version", old, tiny_weights)
    # Garbage.
    isr("config_garbage", '{"model": {"embed_dim": 2,,, ]]\n\x00\x7f', tiny_weights)
    # A field this build does not know among the network's sizes (a newer build's option, which
    # would change the network the weights belong to).
    unknown = json.loads(json.dumps(tiny_config))
    unknown["model"]["attention_kind"] = "linear"
    isr("config_unknown_field", unknown, tiny_weights)
    # config.json's embed_dim changed (2 -> 4), so the weights do not fit.
    wider = json.loads(json.dumps(tiny_config))
    wider["model"]["embed_dim"] = 4
    isr("weights_wrong_shape", wider, tiny_weights)
    # The generic config with its weights cut to 4 KB.
    isr("weights_truncated", config, truncated)
    # A complete ISR, but a models.json and a coarse.json that are not what they should be.
    isr("manifest_garbage", tiny_config, tiny_weights)
    write("models/manifest_garbage/models.json", '{"format_version": 1, "best": \n')
    isr("manifest_future", tiny_config, tiny_weights)
    manifest = {
        "format_version": 7,
        "scene": "corpus",
        "held_out": "none",
        "protocol": "none",
        "paths": {"coarse_alone": {"fine_error_mm": 1.0}},
        "best": "coarse_alone",
    }
    write("models/manifest_future/models.json", json.dumps(manifest, indent=2) + "\n")
    isr("coarse_garbage", tiny_config, tiny_weights)
    write("models/coarse_garbage/coarse.json", '{"compression": "lots", "friction": -1}\n')


def make_misc():
    # A triangle as ASCII PLY: a real mesh format, but not one clothsr reads.
    write(
        "misc/unsupported.ply",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    )


def main():
    for sub in OWNED:
        shutil.rmtree(HERE / sub, ignore_errors=True)
    make_usd()
    make_obj()
    make_patterns()
    make_models()
    make_misc()
    total = 0
    for path in sorted(HERE.rglob("*")):
        if path.is_file() and path.relative_to(HERE).parts[0] in OWNED:
            size = path.stat().st_size
            assert size < MAX_FILE, f"{path}: {size} bytes"
            total += size
    assert total < MAX_TOTAL, f"corpus is {total} bytes"
    # Every text stage must parse, except the ones broken on purpose.
    unparsable = {"not_usd.usda"}
    for path in sorted((HERE / "usd").glob("*.usda")):
        if path.name not in unparsable:
            assert Sdf.Layer.OpenAsAnonymous(str(path)) is not None, path
    print(f"wrote the corpus: {total} bytes")


if __name__ == "__main__":
    main()
