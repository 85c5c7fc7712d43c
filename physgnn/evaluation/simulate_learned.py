"""The learned simulator of a trained run rolled out on one scene's truth for ``simulate``
(:mod:`physgnn.evaluation.simulate`): from the truth's first H+1 frames, followed by the
constraint stage on request, compiled first on request with a failing compile told in one line
naming ``paths.compile_cache``; returns the prediction and where it came from."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from physgnn.errors import PhysgnnError, disk_problem, one_line
from physgnn.evaluation.simulate_options import SimulateError
from physgnn.files import portable
from physgnn.models.capture import compile_simulator, compiled_graphs
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.models.settings import torch_threads
from physgnn.physics.trajectory import Trajectory
from physgnn.rollout import rollout
from physgnn.training.runs import GIVE_A_RUN, load_run, resolve_run

# Above this many sphere-frames a simulation shows its progress (it takes more than seconds).
LONG = 100_000


def rollout_prediction(simulator, truth: Trajectory) -> Trajectory:
    """The simulator's rollout of ``truth`` from its first H+1 frames (finite prefix)."""
    return rollout(simulator, [truth])[0]


def learned(
    run_dir: str,
    truth: Trajectory,
    constraints: int = 0,
    compile_cache: str | None = None,
    threads: int | None = None,
) -> tuple[Trajectory, dict]:
    """Roll the run's simulator out on ``truth`` (with ``constraints`` > 0, followed by the
    constraint stage, :mod:`physgnn.models.constrained`; with a ``compile_cache`` folder,
    compiled, :func:`compile_ahead`) on ``threads`` torch threads (None: the process's);
    returns the prediction and where it came from: ``{"checkpoint", "run", "H",
    "constraints", "threads", "ms_per_frame", "compile_s", "cfg"}``."""
    folder = resolve_run(run_dir)
    if not folder.is_dir():
        raise SimulateError(f"run folder {run_dir} does not exist: {GIVE_A_RUN}")
    simulator, cfg, info = load_run(folder)
    history = int(simulator.H)
    fresh = compile_cache is not None and not any(Path(compile_cache).glob("*"))
    compile_s = None
    with compile_guard(compile_cache), torch_threads(threads) as ran_on:
        if compile_cache is not None:
            compile_s = compile_ahead(simulator, truth, compile_cache)
        if constraints > 0:
            simulator = ConstrainedSimulator(simulator, constraints)
        if truth.n_spheres * truth.n_frames >= LONG:
            print(
                f"rolling the learned simulator out: {truth.n_spheres} spheres, {truth.n_frames} "
                "frames ...",
                file=sys.stderr,
                flush=True,
            )
        graphs = compiled_graphs()
        start = time.perf_counter()
        pred = rollout_prediction(simulator, truth)
    steps = max(pred.n_frames - history - 1, 1)
    graphs = compiled_graphs() - graphs
    if compile_s is not None and graphs > 0 and fresh:  # a second call loaded them: no note
        print(
            f"note: ms_per_frame includes compiling {graphs} more graph(s) "
            "for edge counts the first frames did not have (0 or 1 pair); a second call "
            "loads them from paths.compile_cache",
            file=sys.stderr,
        )
    source = {"checkpoint": str(info.get("checkpoint", run_dir)), "run": portable(folder)}
    source |= {"H": history, "constraints": constraints, "cfg": cfg, "compile_s": compile_s}
    source["threads"] = ran_on
    source["ms_per_frame"] = 1000 * (time.perf_counter() - start) / steps
    return pred, source


@contextmanager
def compile_guard(cache_dir: str | None) -> Iterator[None]:
    """With a compile cache (``cache_dir``; None: nothing guarded), a failing compile is one
    line naming ``paths.compile_cache``: a full, read-only or forbidden one (the files this
    compile left there removed), or one that may be corrupt (truncated ``.so`` files), with
    how to clear it."""
    if cache_dir is None:
        yield
        return
    cache = Path(cache_dir)
    before = set(cache.rglob("*")) if cache.is_dir() else set()
    try:
        yield
    except (PhysgnnError, KeyboardInterrupt):
        raise
    except Exception as err:
        failed = err
    else:
        return
    disk = next((e for e in _chain(failed) if disk_problem(e)), None)
    what = f"{type(failed).__name__}: {one_line(failed)}"[:300]
    reason = disk and (getattr(disk, "strerror", None) or "disk full or read-only")
    del failed, disk  # their frames hold the compiler's open files
    if reason is None:
        raise SimulateError(
            f"compiling the learned step failed ({what}); the compile cache "
            f"paths.compile_cache={cache} may be corrupt (truncated files): clear it (rm -r "
            f"{cache}) and run again, or run with compile=false"
        )
    for path in sorted(set(cache.rglob("*")) - before, reverse=True):  # files, then folders
        try:
            path.unlink() if path.is_file() or path.is_symlink() else path.rmdir()
        except OSError:
            pass
    raise SimulateError(
        f"paths.compile_cache={cache} cannot be written ({reason}; what this compile wrote "
        "there was removed): free space there, or choose a writable paths.compile_cache (or "
        "compile=false)"
    )


def _chain(err: BaseException) -> Iterator[BaseException]:
    """``err`` and the errors it was raised from or during (inductor wraps a failed write)."""
    seen = set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        yield err
        err = err.__cause__ or err.__context__


def compile_ahead(simulator, truth: Trajectory, cache_dir: str) -> float:
    """Seconds to compile ``simulator``'s step (:func:`~physgnn.models.capture.compile_simulator`,
    its code kept in ``cache_dir``) on a few frames of ``truth``, so that the timed rollout
    after it runs compiled code only."""
    print("compiling the learned step ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    compile_simulator(simulator, cache_dir=cache_dir)
    rollout(simulator, [truth.truncated(min(int(simulator.H) + 3, truth.n_frames))])
    return time.perf_counter() - start
