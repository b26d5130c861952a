"""Writes docs/gallery/README.md from make.sh's runs: per garment, what dressing took, the
seams, the fine vertices inside the body before the push-out, whether the garment kept its
place on the body through the walk, and the run's pace (from the runs' logs and outputs).

    .venv/bin/python docs/gallery/table.py OUT_DIR FRAMES > docs/gallery/README.md
"""

import pathlib
import re
import sys

import numpy as np
from pxr import Usd, UsdGeom


def field(pattern, text, cast=float, default=None):
    m = re.search(pattern, text)
    return cast(m.group(1)) if m else default


def slide_mm(usd):
    """How far the garment's top edge slides on the body over the shot, mm: the largest change
    from the first frame of the height of the garment's top (the 99.5th percentile of its
    heights) above the body ring it sits on at the first frame (the body's vertices within
    2 cm of that height under the garment). A bodice or waistband slipping down shows here;
    the walk moves the ring and the garment together."""
    stage = Usd.Stage.Open(str(usd))
    garments, body = [], None
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Mesh):
            continue
        path = str(prim.GetPath())
        if "/Garments/" in path:
            garments.append(UsdGeom.Mesh(prim))
        elif "/Colliders/" in path and body is None:
            body = UsdGeom.Mesh(prim)
    if not garments or body is None:
        return float("nan")
    start, end = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    ring, heights = None, []
    for f in range(max(start, 1), end + 1):
        g = np.concatenate([np.asarray(m.GetPointsAttr().Get(f)) for m in garments])
        b = np.asarray(body.GetPointsAttr().Get(f))
        top = np.percentile(g[:, 1], 99.5)
        if ring is None:
            lo, hi = g[:, [0, 2]].min(0) - 0.01, g[:, [0, 2]].max(0) + 0.01
            xz = b[:, [0, 2]]
            ring = (np.abs(b[:, 1] - top) < 0.02) & (xz >= lo).all(1) & (xz <= hi).all(1)
            if not ring.any():
                return float("nan")
        heights.append(top - b[ring, 1].mean())
    heights = np.asarray(heights)
    return 1e3 * np.abs(heights - heights[0]).max()


def main(out, frames):
    rows = []
    logs = sorted(pathlib.Path(out).glob("mh_*.log")) + sorted(pathlib.Path(out).glob("outfit_*.log"))
    for log in logs:
        g = log.stem
        t = log.read_text(errors="replace")
        t = re.sub(r"\x1b\[[0-9;]*m", "", t)
        if "fine vertices pushed out" not in t:
            last = [line for line in t.splitlines() if "dressing:" in line][-1:]
            why = last[0].split("INFO ")[-1].strip() if last else "see its log"
            rows.append(f"| `{g}` | did not finish in the time limit; last: {why} ||||||||||")
            continue
        setup = field(r"set up in ([0-9.]+) s", t)
        coarse = field(r"coarse (\d+) vertices", t, int)
        fine = field(r"fine (\d+) vertices", t, int)
        sew = field(r"dressed: (\d+) sewing", t, int)
        gap = field(r"widest seam gap ([0-9.]+) mm", t.split("dressed:")[-1])
        welded = field(r"(\d+ of \d+) seam pairs welded", t, str, "–")
        inside = field(r"colliders: ([0-9.]+) a frame inside one", t, float, 0.0)
        deepest = field(r"inside one \(deepest ([0-9.]+) mm", t, float, 0.0)
        overlap = field(r"([0-9.]+) where a collider overlaps itself", t, float)
        per_frame = field(r"per frame: simulator ([0-9.]+) s", t)
        msr = field(r"MSR ([0-9.]+) s\n", t + "\n")
        share = 100.0 * inside / fine if fine else float("nan")
        # Outside the body's own overlap (thighs passing into each other), where a place
        # outside the body exists.
        if overlap is None:
            clear = "–"
        else:
            clear = f"{inside - overlap:.0f} ({100.0 * (inside - overlap) / fine:.2f} %)" if fine else "–"
        pace = f"{per_frame + msr:.2f}" if per_frame is not None and msr is not None else "–"
        usd = pathlib.Path(out) / f"{g}.usdc"
        check = pathlib.Path(out) / f"{g}.eval.txt"
        check = check.read_text() if check.exists() else ""
        crossings = field(r"cloth through cloth: ([0-9.]+) edge", check)
        between = field(r"\(([0-9.]+) between garments\)", check)
        through = "–" if crossings is None else f"{crossings:.0f}"
        if between:
            through += f" ({between:.0f} between garments)"
        slide = slide_mm(usd) if usd.exists() else float("nan")
        imgs = " ".join(
            f"![{g} frame {f}]({g}_f{f}_three-quarter.png)"
            for f in (1, frames // 2, frames)
        )
        rows.append(
            f"| `{g}` | {coarse} / {fine} | {setup:.1f} | {sew} | {welded} | {gap:.1f} | "
            f"{inside:.0f} ({share:.2f} %, {deepest:.1f} mm) | {clear} | {through} | {slide:.0f} | "
            f"{pace} |"
        )
        rows.append(f"| {imgs} |||||||||||")
    print("# Garments people wear\n")
    print(
        "Every MakeHuman garment of `tests/data/patterns`, and an outfit of two, on the walking avatar "
        "(`tests/data/avatars`), through `clothsr run` with the generic models; frames 1, "
        f"{frames // 2} and {frames} rendered by `tools/render.py`. Made by `make.sh` in this "
        "folder. Times are wall times as `make.sh` ran, beside whatever else the machine ran; "
        "`docs/experiments/garments.md` has times measured alone. Edges through cloth: "
        "`clothsr eval --pred`'s count of fine edges passing through a fine triangle of the "
        "same garment or another (a layer through a layer). Cloth inside the body where the body "
        "overlaps itself (inside two of its parts at once, by the body's winding number: the "
        "walking avatar's thighs pass into each other) has no place outside near it; the column "
        "beside counts the rest.\n"
    )
    print(
        "| garment | vertices coarse / fine | set-up s | sewing steps | seam pairs welded | "
        "widest open seam mm | "
        "fine vertices inside the body a frame, before the push-out (share, deepest) | "
        "of those, outside the body's own overlap (share) | fine edges through fine cloth a frame | top edge slid mm | s a frame |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
