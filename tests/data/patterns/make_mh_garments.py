"""Makes the GarmentCode sewing patterns fitted to the MakeHuman body (tests/data/patterns/mh_*/).

Usage (from anywhere; paths default to this script's folder and ../avatars):

    python make_mh_garments.py GARMENTCODE_DIR [--out DIR] [--body-yaml YAML] [--avatar USD]
                               [--only NAME ...] [--check-only]

* GARMENTCODE_DIR: a checkout (work tree) of https://github.com/maria-korosteleva/GarmentCode at commit
  d449629 ("Merge pull request #50 from llada60/fix_uv_connected"), MIT License. The garment programs
  (assets/garment_programs), the design defaults (assets/design_params/default.yaml), the body-parameter class
  (assets/bodies/body_params.py) and the `pygarment` package are all taken from this checkout; nothing is copied
  into this repository. `git archive` of that commit works; its pygarment/pattern/cairo_dlls (Windows DLLs,
  partly missing from some mirrors) are not needed on Linux.
* Python >= 3.9 with GarmentCode's dependencies: pyyaml, numpy, scipy, svgpathtools, svgwrite, cairosvg (needs the
  system libcairo), matplotlib, plus libigl (the `igl` module: point/mesh distance and winding number for the
  placement check) and usd-core (`pxr`, reads the avatar). All are on PyPI; `pip install pygarment==2.0.2 usd-core`
  pulls in all of them (the `pygarment` package itself is not used: the checkout's copy is).
* --body-yaml: GarmentCode body measurements (default: mh_base_body.yaml next to this script).
* --avatar: the body whose frame-0 pose the patterns are placed around (default: ../avatars/mh_walk_train.usda,
  UsdSkel, metres, y-up, facing +z; frame 0 = rest A-pose). A plain Mesh with time-sampled points works too.
* --out: where the mh_<name>/ folders are written (default: this script's folder).
* --only: make only these garments (names from GARMENTS below, e.g. mh_pants).
* --check-only: do not write anything; run the placement check on the existing mh_*/ specifications in --out
  (also works for the older mh_tshirt, mh_pencil_skirt, mh_skirt_circle given with --only).

GarmentCode collects sub-components in a Python set of objects, so the order of the `panels` keys and of the
`stitches` list in its JSON changes from run to run (same content). The script rewrites the JSON with the panels
in the pattern's own `panel_order` and the stitches sorted by (panel_order index, edge id) of both sides, so that
two runs give byte-identical files; nothing else in the JSON is changed.

For each garment the script loads GarmentCode's default design, sets the few values listed in GARMENTS,
builds `MetaGarment(name, body, design)`, moves the panels listed under "move" (translation only), and writes
mh_<name>/: <name>_specification.json, <name>_pattern.svg/.png (GarmentCode's serializer, no labels, no 3D view),
design_params.yaml (full design used) and body_measurements.yaml (body incl. GarmentCode's derived `_` fields,
full float precision).

Placement check: every panel is sampled in its 2D frame (outline at <= 1 cm arc-length spacing plus a 1 cm grid of
interior points), put into 3D with the panel's rotation (GarmentCode's intrinsic XYZ Euler angles, degrees) and
translation (cm), and compared with the avatar's frame-0 surface (scaled to cm): clearance = distance to the surface,
"inside" = generalized winding number > 0.5. The script prints the smallest clearance per panel and fails (exit 1)
if any sample point of a garment it made or checked is inside the body.
"""

import argparse
import copy
import json
import os
import sys
from pathlib import Path

import numpy as np
import yaml

HERE = Path(__file__).resolve().parent

# name -> design values (dotted path under `design:` -> value of its `v` field) and panel moves
# (panel name -> new translation [x, y, z] in cm). Everything not listed keeps GarmentCode's default.
GARMENTS = {
    'mh_dress_strapless': {
        'design': {
            'meta.upper': 'FittedShirt',
            'meta.bottom': 'PencilSkirt',
            'shirt.strapless': True,
            'collar.bc_depth': 0.7,  # default 0: the strapless back would rise to the neck base
        },
        'move': {},
    },
    'mh_dress_straps': {
        'design': {
            'meta.upper': 'FittedShirt',
            'meta.bottom': 'PencilSkirt',
            'pencil-skirt.flare': 1.2,  # slight A-line; sleeveless (default) = shoulder straps
        },
        'move': {},
    },
    'mh_shirt_sleeves': {
        'design': {
            'meta.upper': 'Shirt',
            'sleeve.sleeveless': False,
            'sleeve.length': 0.75,  # 3/4; at 1.0 the front sleeve panels cross the hands
        },
        'move': {},
    },
    'mh_pants': {
        'design': {
            'meta.bottom': 'Pants',
            'pants.length': 0.9,
        },
        'move': {},
    },
    'mh_jumpsuit': {
        'design': {
            'meta.upper': 'FittedShirt',
            'meta.bottom': 'Pants',
            'pants.length': 0.8,  # under a top the pants sit 9.5 cm lower: 0.9 would reach below the floor
        },
        'move': {},
    },
    'mh_hoodie': {
        'design': {
            'meta.upper': 'Shirt',
            'collar.component.style': 'Hood2Panels',
            'sleeve.sleeveless': False,
            'sleeve.length': 0.75,
        },
        'move': {},
    },
}


def set_design(design, dotted, value):
    node = design
    for key in dotted.split('.'):
        node = node[key]
    if 'v' not in node:
        raise KeyError(f'{dotted} is not a design parameter')
    node['v'] = value


def canonical_order(spec_file):
    """Rewrites a GarmentCode JSON with panels in `panel_order` and stitches sorted (see the top of the file)."""
    with open(spec_file) as f:
        spec = json.load(f)
    pattern = spec['pattern']
    order = pattern['panel_order']
    rank = {name: i for i, name in enumerate(order)}
    pattern['panels'] = {name: pattern['panels'][name] for name in order}
    pattern['stitches'] = sorted(
        pattern['stitches'],
        key=lambda st: sorted((rank[side['panel']], side['edge']) for side in st))
    with open(spec_file, 'w') as f:
        json.dump(spec, f, indent=2)


# ---------------------------------------------------------------- body

def load_avatar_cm(path):
    """Frame-0 surface of the avatar: (V [n,3] in cm, F [m,3] triangles)."""
    from pxr import Usd, UsdGeom, UsdSkel, Vt

    stage = Usd.Stage.Open(str(path))
    scale = 100.0 * UsdGeom.GetStageMetersPerUnit(stage)
    mesh_prim = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    mesh = UsdGeom.Mesh(mesh_prim)
    t = stage.GetStartTimeCode()
    points = None
    root = next((p for p in stage.Traverse() if p.IsA(UsdSkel.Root)), None)
    if root is not None:
        cache = UsdSkel.Cache()
        cache.Populate(UsdSkel.Root(root), Usd.TraverseInstanceProxies())
        skinning = cache.GetSkinningQuery(mesh_prim)
        if skinning:
            skel_query = cache.GetSkelQuery(UsdSkel.BindingAPI(mesh_prim).GetSkeleton())
            points = Vt.Vec3fArray(mesh.GetPointsAttr().Get())
            skinning.ComputeSkinnedPoints(skel_query.ComputeSkinningTransforms(t), points, t)
    if points is None:
        points = mesh.GetPointsAttr().Get(t)
    xform = np.array(UsdGeom.Xformable(mesh_prim).ComputeLocalToWorldTransform(t), dtype=float)
    V = np.asarray(points, dtype=float)
    if root is None:  # skinned points are already in world space
        V = V @ xform[:3, :3] + xform[3, :3]
    V *= scale
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
    tris, start = [], 0
    for n in counts:
        f = idx[start:start + n]
        start += n
        tris += [[f[0], f[k], f[k + 1]] for k in range(1, n - 1)]
    return V, np.asarray(tris, dtype=np.int64)


# ---------------------------------------------------------------- placement check

def panel_samples(vis_pattern, name, step=1.0):
    """3D sample points (cm) of a panel: outline at <= step spacing + interior grid at step."""
    from matplotlib.path import Path as MPath
    from pygarment.pattern import rotation as rotation_tools

    panel = vis_pattern.pattern['panels'][name]
    verts = np.asarray(panel['vertices'], dtype=float)
    dense = []
    for edge in panel['edges']:
        curve = vis_pattern._edge_as_curve(verts, edge)  # same curve GarmentCode draws
        n = max(8, int(np.ceil(curve.length() / step * 8)))
        dense += [(z.real, z.imag) for z in (curve.point(t) for t in np.linspace(0, 1, n, endpoint=False))]
    dense = np.asarray(dense)
    closed = np.vstack([dense, dense[:1]])
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    ss = np.linspace(0, s[-1], int(np.ceil(s[-1] / step)) + 1)[:-1]
    outline = np.stack([np.interp(ss, s, closed[:, 0]), np.interp(ss, s, closed[:, 1])], 1)
    lo, hi = dense.min(0), dense.max(0)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + step, step), np.arange(lo[1], hi[1] + step, step))
    grid = np.stack([gx.ravel(), gy.ravel()], 1)
    grid = grid[MPath(dense).contains_points(grid)]
    p2 = np.vstack([outline, grid])
    rot = np.asarray(rotation_tools.euler_xyz_to_R(panel['rotation']))
    return np.hstack([p2, np.zeros((len(p2), 1))]) @ rot.T + np.asarray(panel['translation'], dtype=float)


def placement_check(vis_pattern, V, F):
    """{panel: (n_samples, min clearance cm, n inside, max depth inside cm, lowest y cm)}"""
    import igl
    out = {}
    for name in vis_pattern.pattern['panels']:
        p = panel_samples(vis_pattern, name)
        d2, _, _ = igl.point_mesh_squared_distance(p, V, F)
        d = np.sqrt(d2)
        inside = np.abs(igl.fast_winding_number(V, F, p)) > 0.5
        out[name] = (len(p), float(d.min()), int(inside.sum()), float(d[inside].max()) if inside.any() else 0.0,
                     float(p[:, 1].min()))
    return out


def report(name, res):
    ok = all(r[2] == 0 for r in res.values())
    worst = min(res.items(), key=lambda kv: kv[1][1])
    lowest = min(r[4] for r in res.values())
    print(f'{name}: {len(res)} panels, smallest clearance {worst[1][1]:.2f} cm ({worst[0]}), lowest point y = {lowest:.1f} cm'
          + ('' if ok else '  ** PANEL POINTS INSIDE THE BODY **'))
    for pname, (n, clear, n_in, depth, _) in sorted(res.items(), key=lambda kv: kv[1][1]):
        print(f'    {pname:24s} {n:6d} samples  clearance {clear:6.2f} cm'
              + (f'  inside: {n_in} points, up to {depth:.2f} cm deep' if n_in else ''))
    return ok


# ---------------------------------------------------------------- main

def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('garmentcode', type=Path, help='GarmentCode checkout at commit d449629')
    ap.add_argument('--out', type=Path, default=HERE)
    ap.add_argument('--body-yaml', type=Path, default=HERE / 'mh_base_body.yaml')
    ap.add_argument('--avatar', type=Path, default=HERE.parent / 'avatars' / 'mh_walk_train.usda')
    ap.add_argument('--only', nargs='*', default=None)
    ap.add_argument('--check-only', action='store_true')
    args = ap.parse_args()

    gc = args.garmentcode.resolve()
    out_root, body_yaml, avatar = args.out.resolve(), args.body_yaml.resolve(), args.avatar.resolve()
    sys.path.insert(0, str(gc))
    os.chdir(gc)  # GarmentCode's programs open some assets relative to its root
    from assets.bodies.body_params import BodyParameters
    from assets.garment_programs.meta_garment import MetaGarment
    from pygarment.pattern.wrappers import VisPattern

    names = args.only or list(GARMENTS)
    V, F = load_avatar_cm(avatar)
    all_ok = True
    for name in names:
        folder = out_root / name
        if args.check_only:
            vis = VisPattern(str(folder / f'{name}_specification.json'))
            all_ok &= report(name, placement_check(vis, V, F))
            continue

        spec = GARMENTS[name]
        body = BodyParameters(str(body_yaml))
        with open(gc / 'assets' / 'design_params' / 'default.yaml') as f:
            design = yaml.safe_load(f)['design']
        for key, value in spec['design'].items():
            set_design(design, key, value)
        design_used = copy.deepcopy(design)

        garment = MetaGarment(name, body, design)
        garment.assert_total_length()
        garment.assert_non_empty()
        pattern = garment.assembly()
        for pname, translation in spec['move'].items():
            before = pattern.pattern['panels'][pname]['translation']
            pattern.pattern['panels'][pname]['translation'] = [float(v) for v in translation]
            print(f'{name}: moved {pname} from {before} to {translation}')

        folder.mkdir(parents=True, exist_ok=True)
        pattern.serialize(str(folder), to_subfolder=False, with_3d=False, with_text=False, view_ids=False)
        with open(folder / 'design_params.yaml', 'w') as f:
            yaml.dump({'design': design_used}, f, default_flow_style=False)
        with open(folder / 'body_measurements.yaml', 'w') as f:
            # SafeDumper: pygarment registers a float representer on the default Dumper that keeps 3 digits
            yaml.dump({'body': body.params}, f, default_flow_style=False, Dumper=yaml.SafeDumper)

        canonical_order(folder / f'{name}_specification.json')

        vis = VisPattern(str(folder / f'{name}_specification.json'))
        all_ok &= report(name, placement_check(vis, V, F))
    sys.exit(0 if all_ok else 1)


if __name__ == '__main__':
    main()
