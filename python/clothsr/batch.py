"""Many shots at once: one task per shot, on a Ray cluster or on a local pool of processes;
and a fit's tasks on Ray.

    python -m clothsr.batch SHOT... --out-dir DIR [--models DIR] [--ray ADDRESS|auto|local]
    python -m clothsr.batch SHOT --fit MODELS [--quality preview|final] [--ray ...]

Each shot runs the whole pipeline (:func:`clothsr.run`) into ``DIR/<shot name>.usdc``, in its
own process: a Ray task asking for ``--cpus-per-shot`` CPUs (the Rust side's threads limited to
them), or, without ``--ray``, a child process of a local pool of ``--workers``. Outputs and
their resume points live in ``DIR``, which every worker must see (shared storage), and are
published atomically while a shot runs; a task whose process dies (a killed worker, a lost
node) is run again and resumes from the shot's last published frame. A shot that fails for
bad input or bad usage, or while running, is reported and not retried: the same input fails
the same way. At the end, a table of every shot (or ``--json``: the same summary as the
``clothsr`` command's ``--json``), and the exit code of the most severe failure (0 done, 2 bad
usage, 3 bad input, 4 failure while running).

Workers find the package in the Python environment they run in: install clothsr into the
environment every node of the cluster runs (a shared venv, as the test cluster does), or ship
the wheel with Ray's runtime environment (``runtime_env={"pip": [wheel]}``, passed to
:func:`run_batch`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

from . import _clothsr

PathLike = Union[str, "os.PathLike[str]"]

#: How often a process that died is run again before the shot counts as failed.
RETRIES = 3


def shot_output(scene: PathLike, out_dir: PathLike) -> pathlib.Path:
    """Where a shot's output goes: ``out_dir/<scene's stem>.usdc``, as ``clothsr run --out-dir``."""
    return pathlib.Path(_clothsr.shot_output(os.fspath(scene), os.fspath(out_dir)))


def _shot(scene: str, output: str, error: Optional[Dict[str, str]] = None) -> Dict[str, Any]:
    """A shot's summary before it ran: ``ok`` with nothing computed, or failed with ``error``."""
    return {
        "scene": scene,
        "output": output,
        "status": "ok" if error is None else "failed",
        "frames_computed": 0,
        "resumed_after": None,
        "wall_s": 0.0,
        "error": error,
    }


def run_one(
    scene: str,
    output: str,
    options: Dict[str, Any],
    progress: Optional[Callable[[int, int], None]] = None,
) -> Dict[str, Any]:
    """Runs one shot in this process and returns its summary (the ``clothsr --json`` form of
    a shot): a failure is a summary with its kind and message, never an exception, so that it
    is not retried."""
    from . import BadInputError, UsageError, generic_models

    t0 = time.monotonic()
    summary = _shot(scene, output)
    try:
        report = _clothsr.run(
            scene,
            output,
            options.get("models") or os.fspath(generic_models()),
            frames=options.get("frames"),
            fabric=options.get("fabric", "cotton"),
            avatar=options.get("avatar"),
            corrector=options.get("corrector", "auto"),
            layer=options.get("layer", "auto"),
            publish_every_s=options.get("publish_every_s"),
            progress=progress,
        )
        summary["frames_computed"] = report["frames_computed"]
        summary["resumed_after"] = report["resumed_after"]
    except Exception as e:  # every failure is reported in the summary, not raised
        kind = (
            "usage"
            if isinstance(e, UsageError)
            else "input"
            if isinstance(e, BadInputError)
            else "failure"
        )
        summary["status"] = "failed"
        summary["error"] = {"kind": kind, "message": str(e)}
    summary["wall_s"] = time.monotonic() - t0
    return summary


def summarise(shots: List[Dict[str, Any]], error: Optional[Dict[str, str]] = None) -> Dict[str, Any]:
    """The batch's summary: the ``clothsr --json`` form (status, exit code, error, shots), made
    by the library as the command makes it."""
    text = _clothsr.summarise(json.dumps(shots), json.dumps(error) if error else None)
    return dict(json.loads(text))


class _Board:
    """Frames done per shot, printed as one line whenever it changes (at most once a second)."""

    def __init__(self, n: int, quiet: bool) -> None:
        self.done = [0] * n
        self.total = [0] * n
        self.finished = 0
        self.quiet = quiet
        self.last = ""
        self.last_t = 0.0
        self.lock = threading.Lock()

    def update(self, k: int, done: int, total: int) -> None:
        with self.lock:
            self.done[k], self.total[k] = done, total

    def finish(self, k: int) -> None:
        with self.lock:
            self.finished += 1
            self.done[k] = self.total[k]
        self.show(force=True)

    def show(self, force: bool = False) -> None:
        with self.lock:
            line = (
                f"{self.finished}/{len(self.done)} shots done; frames "
                f"{sum(self.done)}/{sum(self.total) or '?'}"
            )
            now = time.monotonic()
            if self.quiet or line == self.last or (not force and now - self.last_t < 1.0):
                return
            self.last, self.last_t = line, now
        print(f"[{time.strftime('%H:%M:%S')}] {line}", file=sys.stderr, flush=True)


def _local(
    jobs: List[Tuple[str, str]], options: Dict[str, Any], workers: int, cpus: int, board: _Board
) -> List[Dict[str, Any]]:
    """Each shot in a child process (`python -m clothsr.batch --one …`), `workers` at once."""

    def one(k: int) -> Dict[str, Any]:
        scene, output = jobs[k]
        env = dict(os.environ, RAYON_NUM_THREADS=str(cpus))
        for attempt in range(RETRIES + 1):
            # The child reports on a pipe of its own: whatever it (or a library in it) prints
            # goes to stderr and cannot be mistaken for a result.
            read_fd, write_fd = os.pipe()
            cmd = [sys.executable, "-m", "clothsr.batch", "--one", json.dumps([scene, output, options]),
                   "--report-fd", str(write_fd)]
            proc = subprocess.Popen(cmd, stdout=sys.stderr, env=env, pass_fds=(write_fd,))
            os.close(write_fd)
            summary = None
            with os.fdopen(read_fd, "r") as reports:
                for line in reports:
                    try:
                        msg = json.loads(line)
                    except json.JSONDecodeError:
                        continue
                    if "progress" in msg:
                        board.update(k, *msg["progress"])
                        board.show()
                    elif "summary" in msg:
                        summary = msg["summary"]
            proc.wait()
            if summary is not None:
                board.finish(k)
                return dict(summary)
            print(
                f"{scene}: its process ended ({proc.returncode}) with no result; "
                + ("running it again" if attempt < RETRIES else "giving up"),
                file=sys.stderr,
            )
        board.finish(k)
        message = f"{scene}: the process running this shot died {RETRIES + 1} times"
        return _shot(scene, output, {"kind": "failure", "message": message})

    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        return list(pool.map(one, range(len(jobs))))


def _connect(address: str, cpus: int, runtime_env: Optional[Dict[str, Any]]) -> Tuple[Any, Dict[str, Any]]:
    """Ray, connected to the cluster at `address` (or a local instance), and the runtime
    environment of tasks asking for `cpus` CPUs."""
    if address.rsplit(":", 1)[0] in ("127.0.0.1", "localhost"):
        # A cluster bound to the loopback interface (one machine's): Ray would otherwise
        # look for it at the machine's network address. Read when ray is first imported.
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    import ray

    if not ray.is_initialized():
        if address == "local":
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
    env = dict(runtime_env or {})
    env["env_vars"] = dict(env.get("env_vars", {}), RAYON_NUM_THREADS=str(cpus))
    return ray, env


def _ray(
    jobs: List[Tuple[str, str]],
    options: Dict[str, Any],
    address: str,
    cpus: int,
    board: _Board,
    runtime_env: Optional[Dict[str, Any]],
) -> List[Dict[str, Any]]:
    """One Ray task per shot, asking for `cpus` CPUs; progress through an actor."""
    ray, env = _connect(address, cpus, runtime_env)

    @ray.remote(num_cpus=0)
    class Progress:
        def __init__(self, n: int) -> None:
            self.done = [0] * n
            self.total = [0] * n

        def update(self, k: int, done: int, total: int) -> None:
            self.done[k], self.total[k] = done, total

        def get(self) -> Tuple[List[int], List[int]]:
            return self.done, self.total

    @ray.remote(num_cpus=cpus, max_retries=RETRIES, runtime_env=env)  # type: ignore[untyped-decorator]
    def shot_task(k: int, scene: str, output: str, options: Dict[str, Any], board: Any) -> Dict[str, Any]:
        last = [0.0]

        def progress(done: int, total: int) -> None:
            now = time.monotonic()
            if now - last[0] >= 0.5 or done == total:
                last[0] = now
                board.update.remote(k, done, total)

        return run_one(scene, output, options, progress)

    progress = Progress.remote(len(jobs))  # type: ignore[attr-defined]
    refs = [shot_task.remote(k, s, o, options, progress) for k, (s, o) in enumerate(jobs)]
    index = {r: k for k, r in enumerate(refs)}
    results: List[Optional[Dict[str, Any]]] = [None] * len(jobs)
    pending = list(refs)
    while pending:
        ready, pending = ray.wait(pending, num_returns=1, timeout=1.0)
        for r in ready:
            k = index[r]
            try:
                results[k] = ray.get(r)
            except Exception as e:  # the task's process died more often than it is retried
                scene, output = jobs[k]
                results[k] = _shot(scene, output, {"kind": "failure", "message": f"{scene}: {e}"})
            board.finish(k)
        done, total = ray.get(progress.get.remote())
        for k, (d, t) in enumerate(zip(done, total)):
            board.update(k, d, t)
        board.show()
    return [r for r in results if r is not None]


def run_batch(
    shots: Sequence[PathLike],
    out_dir: PathLike,
    *,
    models: Optional[PathLike] = None,
    frames: Optional[int] = None,
    fabric: str = "cotton",
    avatar: Optional[PathLike] = None,
    corrector: str = "auto",
    layer: Optional[bool] = None,
    publish_every_s: Optional[float] = None,
    ray: Optional[str] = None,
    cpus_per_shot: int = 1,
    workers: Optional[int] = None,
    runtime_env: Optional[Dict[str, Any]] = None,
    quiet: bool = False,
) -> Dict[str, Any]:
    """Runs every shot into ``out_dir`` and returns the batch's summary (see the module's
    documentation): on Ray when ``ray`` is a cluster address, ``"auto"`` (the cluster this
    machine belongs to) or ``"local"`` (a Ray instance started here), else on a local pool of
    ``workers`` processes (default: the CPUs over ``cpus_per_shot``). The other arguments are
    :func:`clothsr.run`'s, for every shot."""
    out = pathlib.Path(out_dir)
    if not out.is_dir():
        return summarise([], {"kind": "usage", "message": f"{out}: the output folder does not exist"})
    if cpus_per_shot < 1:
        return summarise([], {"kind": "usage", "message": "cpus_per_shot must be at least 1"})
    seen: Dict[str, str] = {}
    jobs = []
    for s in shots:
        o = shot_output(s, out)
        if o.name in seen:
            return summarise(
                [],
                {
                    "kind": "usage",
                    "message": f"{s} and {seen[o.name]} would both write {o}: rename one",
                },
            )
        seen[o.name] = os.fspath(s)
        jobs.append((os.path.abspath(s), os.path.abspath(o)))
    options = {
        "models": os.path.abspath(models) if models is not None else None,
        "frames": frames,
        "fabric": fabric,
        "avatar": os.path.abspath(avatar) if avatar is not None else None,
        "corrector": corrector,
        "layer": {None: "auto", True: "on", False: "off"}[layer],
        "publish_every_s": publish_every_s,
    }
    board = _Board(len(jobs), quiet)
    if ray is None:
        n = workers or max(1, (os.cpu_count() or 1) // cpus_per_shot)
        shots_out = _local(jobs, options, n, cpus_per_shot, board)
    else:
        shots_out = _ray(jobs, options, ray, cpus_per_shot, board, runtime_env)
    return summarise(shots_out)


def fit(
    shot: PathLike,
    output: PathLike,
    *,
    ray: Optional[str] = None,
    cpus_per_task: int = 1,
    runtime_env: Optional[Dict[str, Any]] = None,
    quality: str = "preview",
    fabric: str = "cotton",
    avatar: Optional[PathLike] = None,
    colliders: Sequence[PathLike] = (),
    frames: Optional[int] = None,
    isr_steps: Optional[int] = None,
    from_scratch: bool = False,
    coarse_mm: Optional[float] = None,
    fine_mm: Optional[float] = None,
    quiet: bool = False,
) -> pathlib.Path:
    """:func:`clothsr.fit` with its plan's tasks as Ray tasks: the simulations of the shot's
    variations fan out over the cluster, each task once those it needs are done (the training
    and the calibration after the data sets), all in the folder ``output``, which every node
    must see. The models are those a local fit makes, bit for bit where the training runs on
    the same number of threads (``cpus_per_task``). A task whose process dies runs again and
    resumes (a data set from its last frame, a training from its last checkpoint); a task
    that fails raises its error here. Without ``ray``, the tasks run here in order."""
    from . import generic_models

    out = pathlib.Path(output)
    generic_isr = None if from_scratch else os.fspath(generic_models() / "isr")
    tasks = _clothsr.fit_plan(
        os.fspath(shot),
        os.fspath(out),
        generic_isr=generic_isr,
        quality=quality,
        fabric=fabric,
        avatar=os.fspath(avatar) if avatar is not None else None,
        colliders=[os.fspath(c) for c in colliders],
        frames=frames,
        isr_steps=isr_steps,
        coarse_mm=coarse_mm,
        fine_mm=fine_mm,
    )
    out = out.resolve()

    def say(line: str) -> None:
        if not quiet:
            print(f"[{time.strftime('%H:%M:%S')}] {line}", file=sys.stderr, flush=True)

    if ray is None:
        for k, (task_id, _) in enumerate(tasks):
            say(f"task {k + 1}/{len(tasks)}: {task_id}")
            _clothsr.fit_task(os.fspath(out), task_id)
        return out
    ray_mod, env = _connect(ray, cpus_per_task, runtime_env)

    @ray_mod.remote(num_cpus=cpus_per_task, max_retries=RETRIES, runtime_env=env)  # type: ignore[untyped-decorator]
    def fit_task(folder: str, task_id: str, *needs: str) -> str:
        _clothsr.fit_task(folder, task_id)
        return task_id

    refs: Dict[str, Any] = {}
    for task_id, after in tasks:
        refs[task_id] = fit_task.options(name=f"fit_task:{task_id}").remote(
            os.fspath(out), task_id, *[refs[a] for a in after]
        )
    pending = list(refs.values())
    while pending:
        ready, pending = ray_mod.wait(pending, num_returns=1)
        for r in ready:
            try:
                done = ray_mod.get(r)
            except ray_mod.exceptions.RayTaskError as e:
                raise e.as_instanceof_cause() from None
            say(f"{len(tasks) - len(pending)}/{len(tasks)} tasks done ({done})")
    return out


def format_table(summary: Dict[str, Any]) -> str:
    """The summary as a table: one row per shot."""
    rows = [f"{'shot':<32} {'status':<7} {'frames':>6} {'resumed':>8} {'wall s':>8}  error"]
    for s in summary["shots"]:
        err = s["error"]["kind"] + ": " + s["error"]["message"] if s.get("error") else ""
        resumed = "" if s.get("resumed_after") is None else str(s["resumed_after"])
        rows.append(
            f"{pathlib.Path(s['scene']).name:<32} {s['status']:<7} {s['frames_computed']:>6} "
            f"{resumed:>8} {s['wall_s']:>8.1f}  {err}"
        )
    if summary.get("error"):
        rows.append(f"error: {summary['error']['message']}")
    return "\n".join(rows)


def _one(arg: str, report_fd: Optional[int]) -> int:
    """A local pool's child: runs one shot, writing progress and its summary as JSON lines to
    the file descriptor ``report_fd`` (default: stdout)."""
    scene, output, options = json.loads(arg)
    reports = os.fdopen(report_fd, "w") if report_fd is not None else sys.stdout

    def report(msg: Dict[str, Any]) -> None:
        reports.write(json.dumps(msg) + "\n")
        reports.flush()

    def progress(done: int, total: int) -> None:
        report({"progress": [done, total]})

    summary = run_one(scene, output, options, progress)
    report({"summary": summary})
    return 0


def main(argv: Optional[Sequence[str]] = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m clothsr.batch",
        description="Run clothsr on many shots: one task per shot, on Ray or a local pool.",
    )
    p.add_argument("shots", nargs="*", help="shots: USD, GarmentCode JSON or OBJ")
    p.add_argument("--out-dir", help="output folder (shared by every worker): DIR/<shot>.usdc")
    p.add_argument("--models", help="models folder (default: the generic models)")
    p.add_argument("--frames", type=int, help="frames of each shot (default: its range)")
    p.add_argument("--fabric", default="cotton", help="fabric preset for garments without one")
    p.add_argument("--avatar", help="avatar for every shot (USD, UsdSkel or point cache)")
    p.add_argument("--corrector", default="auto", choices=["auto", "on", "off"])
    p.add_argument("--layer", default="auto", choices=["auto", "on", "off"])
    p.add_argument(
        "--publish-every-s", type=float, help="seconds between resume points (default 10)"
    )
    p.add_argument(
        "--ray",
        metavar="ADDRESS|auto|local",
        help="run on Ray: a cluster's address, auto (this machine's cluster) or local",
    )
    p.add_argument("--cpus-per-shot", type=int, default=1, help="CPUs each shot asks for")
    p.add_argument("--workers", type=int, help="without --ray: shots at once (default: CPUs)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument(
        "--fit",
        metavar="MODELS",
        help="fit models for the one shot given into MODELS, its tasks on Ray (clothsr fit)",
    )
    p.add_argument("--quality", default="preview", choices=["preview", "final"])
    p.add_argument("--one", help=argparse.SUPPRESS)
    p.add_argument("--report-fd", type=int, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.one is not None:
        return _one(args.one, args.report_fd)
    if args.fit is not None:
        if len(args.shots) != 1:
            p.error("--fit takes one shot")
        fit(
            args.shots[0],
            args.fit,
            ray=args.ray,
            cpus_per_task=args.cpus_per_shot,
            quality=args.quality,
            fabric=args.fabric,
            avatar=args.avatar,
            frames=args.frames,
        )
        return 0
    if not args.shots or not args.out_dir:
        p.error("give the shots and --out-dir")
    # Stdout carries the result alone: what Ray prints on the driver goes to stderr.
    with contextlib.redirect_stdout(sys.stderr):
        summary = _run_from_args(args)
    print(json.dumps(summary) if args.json else format_table(summary))
    return int(summary["exit_code"])


def _run_from_args(args: argparse.Namespace) -> Dict[str, Any]:
    return run_batch(
        args.shots,
        args.out_dir,
        models=args.models,
        frames=args.frames,
        fabric=args.fabric,
        avatar=args.avatar,
        corrector=args.corrector,
        layer={"auto": None, "on": True, "off": False}[args.layer],
        publish_every_s=args.publish_every_s,
        ray=args.ray,
        cpus_per_shot=args.cpus_per_shot,
        workers=args.workers,
        quiet=args.json,
    )


if __name__ == "__main__":
    sys.exit(main())
