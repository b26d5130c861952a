#!/usr/bin/env python3
"""Side-by-side peer benchmark: the clothsr drape scene run in NVIDIA Newton 1.8 (Warp, CPU backend).

Scene (identical for every solver and resolution)
    * A square cloth sheet, 1 m x 1 m, built with ``add_cloth_grid`` as an N x N vertex grid
      (``3k``: 55 x 55 = 3,025 vertices, 5,832 triangles; ``40k``: 201 x 201 = 40,401 vertices,
      80,000 triangles), lying flat (normal along +Z) at height z = 0.32 m, centred over the origin.
    * A static collision sphere of radius 0.3 m centred at the origin, so the sheet starts 2 cm
      above its top. Cloth-sphere contact is on (Newton's ``CollisionPipeline`` soft contacts,
      re-detected every step); cloth self-collision is off for every solver (see below).
    * Gravity -9.81 m/s^2 along Z (Newton's default up axis), dt = 1/300 s, 10 solver iterations
      per step (``SolverStyle3D.Config(iterations=10)``, ``SolverXPBD(iterations=10)``,
      ``SolverVBD(iterations=10)``). Areal density 0.2 kg/m^2, particle (contact) radius 5 mm.
    * Material parameters follow Newton's own cloth examples for each solver (Style3D
      anisotropic stretch/bend from ``example_cloth_style3d``; VBD uses ``example_cloth_twist``'s
      membrane; XPBD uses edge springs, as in ``example_cloth_hanging``, because Newton's XPBD
      has no triangle-FEM constraint). Newton's XPBD applies spring corrections Jacobi-style
      without averaging and diverges on this light sheet for springs stiffer than about
      0.1 m/dt^2, so its springs are 0.05 m/dt^2 (0.30 N/m at 3K, 0.022 N/m at 40K): the XPBD
      cloth is far stretchier than the others. The solvers are different methods, so the cloths
      do not behave identically; this is a cost benchmark (the per-step cost does not depend on
      the stiffness values) with a coarse physics sanity check.

Self-collision off means: VBD ``particle_enable_self_contact=False`` (its default); Style3D's
built-in ``Collision`` keeps its cloth-body contact term but its vertex-face, edge-edge and
edge-face stiffnesses are set to 0 (its BVH refit still runs each step); XPBD's
particle-particle hash-grid contacts are disabled. ``--self-collision`` turns them back on
(Style3D with its default self-collision costs ~3x more per step at 3K and ~8x at 40K).
VBD's cost on CPU is dominated by its bending term: the same VBD run without bending
(edge_ke = 0) takes ~35 ms/step at 3K instead of ~130-180.

What is timed
    One step = ``state.clear_forces()`` + ``CollisionPipeline.collide()`` (cloth-sphere contact
    detection) + ``solver.step()``, wall clock, on Warp's CPU device (Warp runs CPU kernels
    serially, so the core count hardly matters). The first ``--warmup`` steps (default 5) are
    not timed: they include Warp's JIT compilation (~40 s per solver when the kernel cache in
    ~/.cache/warp is cold; reported as ``first_step_s``). Then ``--steps`` steps (default 30)
    are timed one by one; ``ms_per_step`` is their median. Model building, graph colouring and
    solver construction are not timed.

Output
    One JSON object per line on stdout (progress and the sanity check go to stderr), e.g.
    {"solver": "xpbd", "verts": 3025, "tris": 5832, "ms_per_step": 12.5, "steps": 30, ...}
    Extra keys: ms_mean, ms_min, ms_max, warmup_steps, first_step_s, setup_s, the cloth's final
    z_min / z_max / z_center (m), sphere_top, dt, iterations, device, newton, warp, and
    loadavg_1min (before, after): other work on the machine (e.g. a cargo build) slows the
    serial Warp kernels, so compare ms_min as well when the load is high.
    After the run the sheet's centre should rest on the sphere (z_center ~ 0.30-0.31 m) and
    its edges should have fallen below the start height; a warning is printed otherwise.

How to run
    bash tools/bench/setup-newton.sh            # once: venv in tools/bench/.venv-newton with newton 1.8
    tools/bench/.venv-newton/bin/python tools/bench/newton_peer.py --res 3k,40k
    tools/bench/.venv-newton/bin/python tools/bench/newton_peer.py --res 40k --solvers style3d --steps 10
    tools/bench/.venv-newton/bin/python tools/bench/newton_peer.py --solvers style3d,xpbd,vbd \\
        --json-out out/newton_peer.jsonl

Options: --res 3k,40k (or a vertex count per side, e.g. 101), --steps N (timed, default 30),
--warmup N (default 5), --solvers style3d,xpbd[,vbd], --json-out FILE (the JSON lines, file
overwritten), --self-collision, --device (default cpu), --verbose (Warp's module-load messages).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np
import warp as wp

# Warp 1.19 logs module loads ("... took N ms (compiled)") at INFO level to stdout; keep them
# quiet by default (``wp.config.quiet`` of older Warp releases no longer exists).
wp.config.log_level = wp.LOG_WARNING

import newton  # noqa: E402
import newton.solvers  # noqa: E402
from newton.solvers import style3d  # noqa: E402

# ----------------------------------------------------------------------------- scene constants
SHEET_SIZE = 1.0  # m, side of the square sheet
SPHERE_RADIUS = 0.3  # m
SHEET_HEIGHT = 0.32  # m, sheet starts 2 cm above the sphere's top
GRAVITY = -9.81  # m/s^2 along +Z (up)
DT = 1.0 / 300.0  # s
ITERATIONS = 10
DENSITY = 0.2  # kg/m^2
PARTICLE_RADIUS = 0.005  # m, contact thickness of each cloth vertex
CONTACT_KE = 1.0e3  # soft (cloth-shape) contact stiffness, used by Style3D and VBD
CONTACT_KD = 1.0e-2
CONTACT_MU = 0.2

# XPBD spring stiffness as a fraction of m/dt^2 (0.30 N/m at 3K, 0.022 N/m at 40K); see build().
XPBD_SPRING_RATIO = 0.05

RES_ALIASES = {"3k": 55, "40k": 201}
SOLVERS = ("style3d", "xpbd", "vbd")


def log(*args):
    print(*args, file=sys.stderr, flush=True)


def parse_res(token: str) -> int:
    token = token.strip().lower()
    if token in RES_ALIASES:
        return RES_ALIASES[token]
    if token.endswith("k"):
        # An approximate vertex count, as clothsr's bench takes it: the nearest square grid.
        return max(2, round((float(token[:-1]) * 1000) ** 0.5))
    n = int(token)
    if n < 2:
        raise ValueError(f"resolution must be at least 2 vertices per side, got {n}")
    return n


def build(solver_name: str, n: int, self_collision: bool, device: str):
    """Build model, solver, states and collision pipeline for an n x n vertex sheet."""
    cells = n - 1
    cell = SHEET_SIZE / cells
    mass = DENSITY * SHEET_SIZE * SHEET_SIZE / (n * n)  # per particle

    builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=(0.0, 0.0, GRAVITY))
    if solver_name == "style3d":
        newton.solvers.SolverStyle3D.register_custom_attributes(builder)

    # Static sphere (body -1 = world), centred at the origin.
    sphere_cfg = newton.ModelBuilder.ShapeConfig()
    sphere_cfg.mu = CONTACT_MU
    builder.add_shape_sphere(-1, xform=wp.transform(wp.vec3(0.0, 0.0, 0.0), wp.quat_identity()),
                             radius=SPHERE_RADIUS, cfg=sphere_cfg, label="sphere")

    grid = {
        "pos": wp.vec3(-0.5 * SHEET_SIZE, -0.5 * SHEET_SIZE, SHEET_HEIGHT),
        "rot": wp.quat_identity(),
        "vel": wp.vec3(0.0, 0.0, 0.0),
        "dim_x": cells,
        "dim_y": cells,
        "cell_x": cell,
        "cell_y": cell,
        "mass": mass,
        "particle_radius": PARTICLE_RADIUS,
    }
    if solver_name == "style3d":
        # example_cloth_style3d's 1 m grid material.
        style3d.add_cloth_grid(
            builder,
            **grid,
            tri_aniso_ke=wp.vec3(1.0e2, 1.0e2, 1.0e1),
            tri_ka=1.0e2,
            tri_kd=2.0e-6,
            edge_aniso_ke=wp.vec3(2.0e-4, 1.0e-4, 5.0e-5),
        )
    elif solver_name == "xpbd":
        # XPBD solves springs + dihedral bending, not triangle FEM: add edge springs. Newton's
        # XPBD sums spring corrections Jacobi-style (no averaging), which diverges on this light
        # sheet once ke*dt^2/m exceeds ~0.1, so the springs are set relative to the particle mass.
        builder.add_cloth_grid(
            **grid,
            add_springs=True,
            spring_ke=XPBD_SPRING_RATIO * mass / DT**2,
            spring_kd=0.0,
            edge_ke=1.0e-3,
            edge_kd=0.0,
        )
    else:  # vbd
        builder.add_cloth_grid(
            **grid,
            tri_ke=1.0e3,
            tri_ka=1.0e3,
            tri_kd=2.0e-4,
            edge_ke=1.0e-3,
            edge_kd=1.0e-2,
        )
        builder.color(include_bending=True)

    model = builder.finalize(device=device)
    model.soft_contact_ke = CONTACT_KE
    model.soft_contact_kd = CONTACT_KD
    model.soft_contact_mu = CONTACT_MU

    if solver_name == "style3d":
        solver = newton.solvers.SolverStyle3D(model, config=newton.solvers.SolverStyle3D.Config(iterations=ITERATIONS))
        if not self_collision:
            # Keep Collision (it also carries cloth-body contact), zero the self-contact terms.
            solver.collision.stiff_vf = 0.0
            solver.collision.stiff_ee = 0.0
            solver.collision.stiff_ef = 0.0
    elif solver_name == "xpbd":
        if not self_collision:
            # XPBD runs particle-particle contacts whenever particle_max_radius > 0.
            model.particle_max_radius = 0.0
            model.particle_grid = None
        solver = newton.solvers.SolverXPBD(model, iterations=ITERATIONS)
    else:
        kwargs = {}
        if self_collision:
            kwargs = {
                "particle_enable_self_contact": True,
                "particle_self_contact_margin": 2.0 * PARTICLE_RADIUS,
                "particle_self_contact_gap": PARTICLE_RADIUS,
            }
        solver = newton.solvers.SolverVBD(model, iterations=ITERATIONS, **kwargs)

    state_0 = model.state()
    state_1 = model.state()
    control = model.control()
    pipeline = newton.CollisionPipeline(model)
    contacts = pipeline.contacts()
    return model, solver, state_0, state_1, control, pipeline, contacts


def run_case(solver_name: str, n: int, steps: int, warmup: int, self_collision: bool, device: str) -> dict:
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    model, solver, s0, s1, control, pipeline, contacts = build(solver_name, n, self_collision, device)
    setup_s = time.perf_counter() - t0

    def step():
        nonlocal s0, s1
        s0.clear_forces()
        pipeline.collide(s0, contacts)
        solver.step(s0, s1, control, contacts, DT)
        s0, s1 = s1, s0

    first_step_s = None
    for i in range(warmup):
        t = time.perf_counter()
        step()
        wp.synchronize_device(device)
        if i == 0:
            first_step_s = time.perf_counter() - t

    times = []
    for _ in range(steps):
        t = time.perf_counter()
        step()
        wp.synchronize_device(device)
        times.append(time.perf_counter() - t)

    q = s0.particle_q.numpy()
    z = q[:, 2]
    centre = q[(n // 2) * n + n // 2]
    if not np.all(np.isfinite(q)):
        log(f"WARNING: {solver_name} {n}x{n}: non-finite particle positions")

    ms = [1e3 * t for t in times]
    from importlib.metadata import version

    return {
        "solver": solver_name,
        "verts": int(model.particle_count),
        "tris": int(model.tri_count),
        "ms_per_step": round(statistics.median(ms), 3) if ms else None,
        "steps": steps,
        "ms_mean": round(statistics.fmean(ms), 3) if ms else None,
        "ms_min": round(min(ms), 3) if ms else None,
        "ms_max": round(max(ms), 3) if ms else None,
        "warmup_steps": warmup,
        "first_step_s": round(first_step_s, 3) if first_step_s is not None else None,
        "setup_s": round(setup_s, 3),
        "grid": f"{n}x{n}",
        "self_collision": self_collision,
        "sim_time_s": round((warmup + steps) * DT, 6),
        "z_min": round(float(z.min()), 5),
        "z_max": round(float(z.max()), 5),
        "z_center": round(float(centre[2]), 5),
        "sphere_top": SPHERE_RADIUS,
        "dt": DT,
        "iterations": ITERATIONS,
        "device": device,
        "loadavg_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "newton": version("newton"),
        "warp": wp.__version__,
    }


def sanity(rec: dict) -> None:
    """Coarse physics check: centre resting on the sphere, edges fallen below the start."""
    msg = (f"{rec['solver']} {rec['verts']} verts after {rec['sim_time_s']:.3f} s: "
           f"z_min={rec['z_min']:.4f} z_max={rec['z_max']:.4f} z_center={rec['z_center']:.4f} "
           f"(start {SHEET_HEIGHT}, sphere top {SPHERE_RADIUS})")
    fall = 0.5 * -GRAVITY * rec["sim_time_s"] ** 2  # free-fall distance over the run
    problems = []
    if fall > SHEET_HEIGHT - SPHERE_RADIUS:  # the centre should have reached the sphere
        if not (SPHERE_RADIUS - 0.02 <= rec["z_center"] <= SPHERE_RADIUS + 0.015):
            problems.append("centre is not resting on the sphere")
        if rec["z_min"] > SHEET_HEIGHT - 0.5 * (SHEET_HEIGHT - SPHERE_RADIUS):
            problems.append("edges have not fallen")
    if rec["z_max"] > SHEET_HEIGHT + 0.05 or rec["z_min"] < -1.0:
        problems.append("cloth left the expected volume")
    log(("ok: " if not problems else "WARNING (" + "; ".join(problems) + "): ") + msg)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--res", default="3k,40k", help="comma list: 3k (55x55), 40k (201x201), another Nk (the nearest square grid) or N (NxN verts)")
    ap.add_argument("--steps", type=int, default=30, help="timed steps per case (default 30)")
    ap.add_argument("--warmup", type=int, default=5, help="untimed warm-up steps incl. JIT (default 5)")
    ap.add_argument("--solvers", default="style3d,xpbd", help="comma list of style3d, xpbd, vbd")
    ap.add_argument("--json-out", default=None, help="also write the JSON lines to this file")
    ap.add_argument("--self-collision", action="store_true", help="turn cloth self-collision on")
    ap.add_argument("--device", default="cpu", help="Warp device (default cpu)")
    ap.add_argument("--verbose", action="store_true", help="show Warp's module-load messages")
    args = ap.parse_args(argv)

    if args.verbose:
        wp.config.log_level = wp.LOG_INFO
    # Whatever a library prints goes to stderr; stdout carries only the JSON lines.
    json_stream = sys.stdout
    sys.stdout = sys.stderr
    if args.warmup < 1:
        ap.error("--warmup must be at least 1 (the first step compiles the kernels)")
    resolutions = [parse_res(r) for r in args.res.split(",") if r.strip()]
    solvers = [s.strip().lower() for s in args.solvers.split(",") if s.strip()]
    for s in solvers:
        if s not in SOLVERS:
            ap.error(f"unknown solver {s!r}; choose from {', '.join(SOLVERS)}")

    wp.init()
    wp.set_device(args.device)
    log(f"newton_peer: newton {newton.__version__}, warp {wp.__version__}, device {args.device}, "
        f"dt={DT:.6f}, iterations={ITERATIONS}, warmup={args.warmup}, steps={args.steps}")

    out = open(args.json_out, "w") if args.json_out else None
    failures = 0
    try:
        for n in resolutions:
            for s in solvers:
                log(f"newton_peer: {s} {n}x{n} ...")
                try:
                    rec = run_case(s, n, args.steps, args.warmup, args.self_collision, args.device)
                except Exception as e:  # report and go on with the other cases
                    failures += 1
                    log(f"newton_peer: {s} {n}x{n} FAILED: {type(e).__name__}: {e}")
                    continue
                line = json.dumps(rec)
                print(line, file=json_stream, flush=True)
                if out:
                    out.write(line + "\n")
                    out.flush()
                sanity(rec)
    finally:
        if out:
            out.close()
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
