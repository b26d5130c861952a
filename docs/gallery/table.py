"""Writes docs/gallery/README.md from the logs of make.sh's runs: per garment, what dressing
took, the seams, the fine vertices inside the body before the push-out, and the run's pace.

    python3 docs/gallery/table.py OUT_DIR FRAMES > docs/gallery/README.md
"""

import pathlib
import re
import sys


def field(pattern, text, cast=float, default=None):
    m = re.search(pattern, text)
    return cast(m.group(1)) if m else default


def main(out, frames):
    rows = []
    for log in sorted(pathlib.Path(out).glob("mh_*.log")):
        g = log.stem
        t = log.read_text(errors="replace")
        t = re.sub(r"\x1b\[[0-9;]*m", "", t)
        setup = field(r"set up in ([0-9.]+) s", t)
        coarse = field(r"coarse (\d+) vertices", t, int)
        fine = field(r"fine (\d+) vertices", t, int)
        sew = field(r"dressed: (\d+) sewing", t, int)
        gap = field(r"widest seam gap ([0-9.]+) mm", t.split("dressed:")[-1])
        inside = field(r"colliders: ([0-9.]+) a frame inside one", t, float, 0.0)
        deepest = field(r"inside one \(deepest ([0-9.]+) mm\)", t, float, 0.0)
        per_frame = field(r"per frame: simulator ([0-9.]+) s", t)
        msr = field(r"MSR ([0-9.]+) s\n", t + "\n")
        share = 100.0 * inside / fine if fine else float("nan")
        pace = f"{per_frame + msr:.2f}" if per_frame is not None and msr is not None else "–"
        imgs = " ".join(
            f"![{g} frame {f}]({g}_f{f}_three-quarter.png)"
            for f in (1, frames // 2, frames)
        )
        rows.append(
            f"| `{g}` | {coarse} / {fine} | {setup:.1f} | {sew} | {gap:.1f} | "
            f"{inside:.0f} ({share:.2f} %, {deepest:.1f} mm) | {pace} |"
        )
        rows.append(f"| {imgs} |||||||")
    print("# Garments people wear\n")
    print(
        "Every MakeHuman garment of `tests/data/patterns` on the walking avatar "
        "(`tests/data/avatars`), through `clothsr run` with the generic models; frames 1, "
        f"{frames // 2} and {frames} rendered by `tools/render.py`. Made by `make.sh` in this "
        "folder.\n"
    )
    print(
        "| garment | vertices coarse / fine | set-up s | sewing steps | seam gap mm | "
        "fine vertices inside the body a frame, before the push-out (share, deepest) | "
        "s a frame |"
    )
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]))
