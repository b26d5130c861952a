"""Throughput of `clothsr.batch` on this machine: the same shots on a local Ray cluster of one
node and of two (one CPU each, on 127.0.0.1), and on the local pool with one and two workers;
shots per hour, and the overhead per task (the batch's wall time beyond its shots' own).

    python tools/bench/ray_throughput.py [FRAMES] [SHOTS]

Each shot is a sample sheet (sphere, three balls, table, in turn) for FRAMES frames (30)
with the generic models, SHOTS of them (4). Prints a Markdown table (docs/scaling.md).
"""

import os
import pathlib
import shutil
import sys
import tempfile
import time

# The cluster is on the loopback interface: read when ray is first imported.
os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")

from clothsr import batch  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
SAMPLES = ["sheet_sphere", "sheet_three_balls", "sheet_table"]


def shots(folder: pathlib.Path, n: int):
    out = []
    for k in range(n):
        p = folder / f"shot{k}.usda"
        shutil.copy(ROOT / "samples" / f"{SAMPLES[k % len(SAMPLES)]}.usda", p)
        out.append(p)
    return out


def measure(label, inputs, frames, n_workers, **kw):
    with tempfile.TemporaryDirectory() as out:
        t0 = time.monotonic()
        s = batch.run_batch(inputs, out, frames=frames, layer=False, quiet=True, **kw)
        wall = time.monotonic() - t0
    assert s["exit_code"] == 0, s
    busy = sum(x["wall_s"] for x in s["shots"])
    return {
        "label": label,
        "workers": n_workers,
        "wall_s": wall,
        "shots_per_hour": len(inputs) * 3600.0 / wall,
        "shot_s": busy / len(inputs),
        # What the batch took beyond its shots' own run times, per shot.
        "overhead_s": (wall * n_workers - busy) / len(inputs),
    }


def main() -> None:
    frames = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        inputs = shots(pathlib.Path(tmp), n)
        for w in (1, 2):
            rows.append(measure(f"local pool, {w} worker(s)", inputs, frames, w, workers=w))
        from ray.cluster_utils import Cluster
        import ray

        for nodes in (1, 2):
            node = {"num_cpus": 1, "node_ip_address": "127.0.0.1"}
            c = Cluster(initialize_head=True, head_node_args=dict(node, include_dashboard=False))
            try:
                for _ in range(nodes - 1):
                    c.add_node(**node)
                rows.append(measure(f"Ray, {nodes} node(s) × 1 CPU", inputs, frames, nodes, ray=c.address))
            finally:
                ray.shutdown()
                c.shutdown()
    print(f"{n} shots × {frames} frames (sample sheets, generic models, 2.5 mm fine)\n")
    print("| where | workers | wall s | shots/hour | run of a shot, s | overhead per shot, s |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['label']} | {r['workers']} | {r['wall_s']:.1f} | {r['shots_per_hour']:.0f} "
            f"| {r['shot_s']:.1f} | {r['overhead_s']:.1f} |"
        )


if __name__ == "__main__":
    main()
