"""Renders docs/images/result.png from a `clothsr run` output (matplotlib, no display needed).

    clothsr lab run samples/sheet_three_balls.usda --models samples/models/three_balls \
        --frames 45 -o out/three_balls.usdc --coarse-out out/three_balls_coarse.usdc
    .venv/bin/python docs/images/render.py out/three_balls_coarse.usdc out/three_balls.usdc \
        45 docs/images/result.png

Draws the coarse (20 mm) sheet the pipeline simulated and the fine (2.5 mm) sheet it made from
it, side by side at one frame, with the colliders.
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import LightSource  # noqa: E402
from pxr import Usd, UsdGeom  # noqa: E402


def meshes(path, frame):
    """(points, triangles, is_collider) of every mesh of the stage at `frame`."""
    stage = Usd.Stage.Open(path)
    out = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        mesh = UsdGeom.Mesh(prim)
        p = np.asarray(mesh.GetPointsAttr().Get(Usd.TimeCode(frame)), dtype=float)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
        idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
        tris, k = [], 0
        for c in counts:
            for j in range(1, c - 1):
                tris.append((idx[k], idx[k + j], idx[k + j + 1]))
            k += c
        collider = "Colliders" in str(prim.GetPath())
        if collider and np.ptp(p[:, 1]) < 0.03:
            continue  # a floor: it would hide the rest
        out.append((p, np.asarray(tris), collider))
    return out


def draw(ax, parts, title):
    light = LightSource(azdeg=315, altdeg=45)
    for p, t, collider in parts:
        # USD is y up; matplotlib's 3D axes are z up.
        x, y, z = p[:, 0], -p[:, 2], p[:, 1]
        colour = (0.7, 0.72, 0.78) if collider else (0.86, 0.42, 0.36)
        ax.plot_trisurf(x, y, z, triangles=t, color=colour, linewidth=0, antialiased=False,
                        shade=True, lightsource=light)
    ax.set_title(title)
    ax.view_init(elev=38, azim=-62)
    ax.set_axis_off()
    ax.set_box_aspect((1, 1, 0.55))


def main(coarse, fine, frame, png):
    frame = float(frame)
    fig = plt.figure(figsize=(12, 5.4), dpi=110)
    a = fig.add_subplot(1, 2, 1, projection="3d")
    b = fig.add_subplot(1, 2, 2, projection="3d")
    fine_parts = meshes(fine, frame)
    draw(a, meshes(coarse, frame), "coarse simulation (20 mm)")
    draw(b, fine_parts, "clothsr's fine mesh (2.5 mm)")
    for ax in (a, b):
        lim = np.concatenate([m[0] for m in fine_parts if not m[2]])
        lo, hi = lim.min(axis=0), lim.max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(-hi[2], -lo[2])
        ax.set_zlim(lo[1], hi[1])
    fig.tight_layout()
    fig.savefig(png)


if __name__ == "__main__":
    main(*sys.argv[1:5])
