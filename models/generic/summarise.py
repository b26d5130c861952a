"""Gathers the held-out figures of models/generic/make.sh's eval stage into the folder's
models.json (the figures `clothsr run` reads) and held_out.md (the tables README.md quotes).

    python3 models/generic/summarise.py DATA OUT [FRAMES [GARMENT_FRAMES]]

DATA is make.sh's data folder (held_out.txt, eval/), OUT the models folder, FRAMES the
held-out shots' length, GARMENT_FRAMES the held-out garment's. Standard library
only. Every figure is a mean over frames; a shot's is the mean over its starts, with the
smallest and largest start beside it.
"""

import csv
import json
import statistics
import sys
from pathlib import Path

STARTS = 3


def series_means(path, column):
    """Mean of `column` over frames, per value of the `series` column."""
    sums = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            s = sums.setdefault(row["series"], [0.0, 0])
            s[0] += float(row[column])
            s[1] += 1
    return {k: v[0] / v[1] for k, v in sums.items()}


def column_mean(path, column):
    """Mean of `column` over frames; None when the file is missing (a stage skipped)."""
    if not Path(path).exists():
        return None
    with open(path, newline="") as f:
        values = [float(r[column]) for r in csv.DictReader(f)]
    return sum(values) / len(values)


def spread(values):
    if any(v is None for v in values):
        return "not run"
    return f"{statistics.mean(values):.2f} ({min(values):.2f}–{max(values):.2f})"


def shot_rows(rows, keys, floor_key):
    """A table row per shot: each key's spread over the starts, then start 0's floor."""
    out = []
    for shot, rs in rows.items():
        fl = rs[0][floor_key]
        cells = [spread([r[k] for r in rs]) for k in keys]
        out.append(f"| {shot} | {' | '.join(cells)} | {'' if fl is None else f'{fl:.2f}'} |")
    return out


def ratio(a, b):
    return "not run" if a is None or b is None else f"{a / b:.2f}"


def main():
    data, out = Path(sys.argv[1]), Path(sys.argv[2])
    frames = int(sys.argv[3]) if len(sys.argv) > 3 else 30
    garment_frames = int(sys.argv[4]) if len(sys.argv) > 4 else 30
    ev = data / "eval"
    shots = [Path(l.strip()).stem for l in open(data / "held_out.txt") if l.strip()]
    rows = {}
    # A shot whose starts are not all evaluated yet (its data still being made) is named as
    # such, and left out of every figure.
    pending = [
        shot
        for shot in shots
        if not all((ev / f"{shot}_s{k}.eval.csv").exists() for k in range(STARTS))
    ]
    for shot in shots:
        if shot in pending:
            continue
        for k in range(STARTS):
            e = ev / f"{shot}_s{k}"
            mm = series_means(f"{e}.eval.csv", "mean_mm")
            bend = series_means(f"{e}.eval.csv", "bend_w1_deg")
            rows.setdefault(shot, []).append(
                {
                    "pipeline": mm["prediction"],
                    "paper_up": mm["paper_upsampled"],
                    "calibrated_up": mm["calibrated_upsampled"],
                    "paper_isr": mm["paper_with_isr"],
                    "floor": mm.get("floor"),
                    "bend_pipeline": bend["prediction"],
                    "bend_paper_up": bend["paper_upsampled"],
                    "bend_floor": bend.get("floor"),
                    "isr": column_mean(f"{e}.sr.csv", "sr_mm"),
                    "int_up": column_mean(f"{e}.sr.csv", "upsampled_mm"),
                    "blind": column_mean(f"{e}.blind.csv", "sr_mm"),
                    "bend_isr": column_mean(f"{e}.sr.csv", "sr_bend_w1_deg"),
                    "bend_int_up": column_mean(f"{e}.sr.csv", "upsampled_bend_w1_deg"),
                    "bend_blind": column_mean(f"{e}.blind.csv", "sr_bend_w1_deg"),
                }
            )
    if not rows:
        print("summarise.py: no held-out shot has all its starts evaluated yet", file=sys.stderr)
        return
    every = [r for rs in rows.values() for r in rs]
    def mean(key, rs=every):
        values = [r[key] for r in rs]
        return None if any(v is None for v in values) else statistics.mean(values)

    def fmt(x):
        return "not run" if x is None else f"{x:.2f}"

    md = [
        "# Held-out figures of the generic models",
        "",
        "Written by `summarise.py` from `make.sh`'s eval stage. The held-out shots of `clothsr lab "
        "scenes --set held-out` (an unseen garment, collider, motion and fabrics), each from three "
        f"starts (the shot as written, and turned and moved), {frames} frames, and a garment no model "
        "saw (GarmentCode's T-shirt in silk, `tshirt-silk-avatar-walk`) on the walk's second second, "
        f"which no training shot reaches, from three starts, {garment_frames} frames; fine "
        "simulations at 2.5 mm in the data mode without self-collision. Mean over frames, per shot "
        "the mean over its starts (smallest–largest start).",
        "",
        *(
            [
                "**Not yet evaluated** (their data is still being made; left out of every "
                "figure below): " + ", ".join(f"`{p}`" for p in pending) + ".",
                "",
            ]
            if pending
            else []
        ),
        "## The whole pipeline (`clothsr run` with these models) against the fine simulation, mm",
        "",
        "| shot | generic models | paper's coarse model, upsampled | calibrated coarse model, "
        "upsampled | paper's coarse model + ISR | floor (start 0) |",
        "|---|---|---|---|---|---|",
    ]
    md += shot_rows(rows, ["pipeline", "paper_up", "calibrated_up", "paper_isr"], "floor")
    md.append(
        f"| **all** | **{mean('pipeline'):.2f}** | {mean('paper_up'):.2f} | "
        f"{mean('calibrated_up'):.2f} | {mean('paper_isr'):.2f} | |"
    )
    md += [
        "",
        f"Generic models / paper's coarse model upsampled: {mean('pipeline') / mean('paper_up'):.2f}×.",
        "",
        "## The ISR alone on the fine simulation's M_int, mm",
        "",
        "| shot | conditioned on the fabric | blind to it | M_int upsampled | conditioned / blind |",
        "|---|---|---|---|---|",
    ]
    for shot, rs in rows.items():
        md.append(
            f"| {shot} | {spread([r['isr'] for r in rs])} | {spread([r['blind'] for r in rs])} | "
            f"{spread([r['int_up'] for r in rs])} | "
            f"{ratio(mean('isr', rs), mean('blind', rs))} |"
        )
    md.append(
        f"| **all** | **{fmt(mean('isr'))}** | {fmt(mean('blind'))} | {fmt(mean('int_up'))} | "
        f"{ratio(mean('isr'), mean('blind'))} |"
    )
    md += [
        "",
        "## Folds and wrinkles in kind: bend angles, degrees",
        "",
        "The 1-Wasserstein distance between the distribution of the angles between neighbouring "
        "fine triangles and the fine simulation's (0: the same folds, wherever they lie). The "
        "floor is the fine simulation's twin from a start 0.1 mm away.",
        "",
        "| shot | whole pipeline | paper's coarse model, upsampled | ISR on M_int, conditioned "
        "| blind | M_int upsampled | floor (start 0) |",
        "|---|---|---|---|---|---|---|",
    ]
    md += shot_rows(
        rows,
        ["bend_pipeline", "bend_paper_up", "bend_isr", "bend_blind", "bend_int_up"],
        "bend_floor",
    )
    md.append("")
    (out / "held_out.md").write_text("\n".join(md))

    manifest = {
        "format_version": 1,
        "scene": "the held-out shots evaluated (of `clothsr lab scenes --set held-out`, and a "
        "T-shirt on the walk): " + ", ".join(s for s in shots if s not in pending),
        "held_out": "data/<shot>_s<k>.manifest.json",
        "protocol": f"Whole pipeline on each held-out shot from three starts, {frames} frames "
        f"({garment_frames} for the T-shirt on the walk; `clothsr lab run` with the start's "
        "variation, then `clothsr eval --gt`), fine output against the "
        "fine simulation, mean over frames, starts and shots; baseline: the simulator's own "
        "(paper's) coarse model, upsampled, from the same starts (`--upsampled-out`). Tables: "
        "held_out.md.",
        "paths": {
            "coarse_alone": {
                "fine_error_mm": round(mean("pipeline"), 3),
                "baseline_mm": round(mean("paper_up"), 3),
            }
        },
        "best": "coarse_alone",
    }
    (out / "models.json").write_text(json.dumps(manifest, indent=2) + "\n")


if __name__ == "__main__":
    main()
