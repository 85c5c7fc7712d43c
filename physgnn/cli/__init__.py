"""The one wrapper of every ``python -m physgnn.<command>``: one config dir, one-line errors.

:func:`command` makes a command's ``main``: Hydra composes ``conf/<name>.yaml`` from the one
absolute config dir :data:`physgnn.CONF_DIR` (so ``main`` runs alike from ``python -m``, a
console script or a test), ``run(cfg)`` does the work and ``done(result)`` (optional) gives
the line to print. An error of the user's making (:class:`~physgnn.errors.PhysgnnError`, a
Hydra or OmegaConf error raised while running, a file missing or already there) is printed
as one line ``error: <message>`` and exits with its ``exit_code`` (2 unless it says
otherwise); anything else is a bug and keeps its traceback. A key added with ``+`` that nothing
reads is refused first (:mod:`physgnn.cli.overrides`). Ctrl-C and SIGTERM print one
line too and exit with 128 + the signal (:class:`~physgnn.errors.Interrupted`).

The command line is checked before anything heavy is imported: a key or an option the config
lacks is one line with the keys most like it (:func:`~physgnn.cli.overrides.check_composes`),
in a second or two, not after the ten seconds torch_geometric and Lightning take to import.
So the work (``run``, ``done``, a ``before`` check that needs it) is given by name,
``"physgnn.training.train:val_loss"``, and imported (:func:`resolve`) only once the command
line composes; a command module imports nothing but this module and light checks.

In a sweep (``-m``, ``hydra.mode=MULTIRUN``) a failing job does not end the sweep: its error
is printed (one line, or the traceback of a bug) and the job returns None; the run records the
failure (``run.json``) and the sweep's summary counts it. An interruption still stops it.

Before the work, torch gets as many threads as the cores other processes leave free
(:func:`free_threads`, measured over a fifth of a second): on a busy machine a second thread
only waits for a core, and steps ran several times slower than on one thread.
``OMP_NUM_THREADS``, when set, wins.
"""

from __future__ import annotations

import functools
import importlib
import math
import os
import sys
import time
import traceback
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import NoReturn

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from hydra.types import RunMode
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from physgnn import CONF_DIR
from physgnn.cli.outputs import OWN_FOLDER, check_outputs_env
from physgnn.cli.overrides import (  # noqa: F401 (compose_config: cli's API)
    check_added_keys,
    check_composes,
    check_quoting,
    compose_config,
)
from physgnn.errors import (
    ConfigError,
    Interrupted,
    PhysgnnError,
    disk_problem,
    interrupt_signal,
    one_line,
    sigterm_interrupts,
)
from physgnn.files import write_text
from physgnn.overrides import given

# A sweep job's folder name (conf/train.yaml: hydra.sweep.subdir) is its overrides: at most
# this many characters (a file name holds 255 bytes), and a path in one (``data.dir=/a/b``)
# with its slashes as ``_``, which would otherwise nest the job folder under ``0_data.dir=``.
DIRNAME_CHARS = 200


def job_dirname(overrides: str) -> str:
    """Hydra's ``override_dirname`` as one folder name (:data:`DIRNAME_CHARS`)."""
    return overrides.replace(os.sep, "_").replace("/", "_")[:DIRNAME_CHARS]


# Registered when any command is imported (a launcher's worker too: it imports the command)
OmegaConf.register_new_resolver("physgnn_dirname", job_dirname, replace=True)

USER_ERRORS = (
    PhysgnnError,
    HydraException,
    OmegaConfBaseException,
    FileNotFoundError,
    FileExistsError,
)


def disk_error(err: BaseException) -> ConfigError:
    """The one line of a :func:`disk_problem`: what, where, and the way out."""
    what = getattr(err, "strerror", None) or "writing failed (disk full or read-only)"
    where = getattr(err, "filename", None) or "the outputs folder"
    return ConfigError(
        f"{what}: {where}; free space, or choose a writable paths.outputs (or PHYSGNN_OUTPUTS)"
    )


def fail(err: BaseException) -> NoReturn:
    """Print ``error: <one line>`` on stderr and exit with the error's code (default 2)."""
    print(f"error: {one_line(err)}", file=sys.stderr)
    sys.exit(getattr(err, "exit_code", 2))


def free_threads() -> int | None:
    """Set torch's threads to the cores this process may run on that other processes leave
    free now (at least 1) and return that count; None (threads untouched) when
    ``OMP_NUM_THREADS`` is set."""
    if os.environ.get("OMP_NUM_THREADS"):
        return None
    import torch  # not at import: a command line is checked before torch is (module doc)

    cpus = own_cpus()
    busy = busy_cores(cpus)
    threads = max(1, min(len(cpus), len(cpus) - math.floor(busy + 0.5)))
    if threads < torch.get_num_threads():
        print(f"threads: {threads} of {len(cpus)} cores ({busy:.1f} busy; OMP_NUM_THREADS=N)")
    torch.set_num_threads(threads)
    return threads


def own_cpus() -> list[int]:
    """The cores this process may run on (its CPU affinity: ``taskset``, a SLURM job's cpuset),
    or every core where the system does not say."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return list(range(os.cpu_count() or 1))


def busy_cores(cpus: list[int], window_s: float = 0.2, stat: str = "/proc/stat") -> float:
    """How many of the cores ``cpus`` other processes keep busy now: their busy share over
    ``window_s`` seconds (Linux ``/proc/stat``, per core) × their count; where there is no
    ``/proc/stat``, the 1-minute load average. Not the load average everywhere: it still
    counts, for about a minute, a process that has ended (``make data`` just before ``make
    train`` left an idle 2-core machine training on one thread), and it counts every core of
    the machine, not the ones a cluster job was given."""
    first = cpu_times(cpus, stat)
    if first is None:
        return os.getloadavg()[0]
    time.sleep(window_s)
    second = cpu_times(cpus, stat)
    busy, total = (b - a for a, b in zip(first, second, strict=True))
    return len(cpus) * busy / total if total > 0 else 0.0


def cpu_times(cpus: list[int], stat: str = "/proc/stat") -> tuple[int, int] | None:
    """``(busy, total)`` clock ticks since boot summed over the ``cpuN`` lines of ``stat`` for
    N in ``cpus`` (user nice system idle iowait irq softirq steal; busy = all but idle and
    iowait); None if it cannot be read or lacks one of them."""
    wanted, busy, total, found = {f"cpu{n}" for n in cpus}, 0, 0, 0
    try:
        with open(stat) as f:
            for line in f:
                fields = line.split()
                if fields and fields[0] in wanted:
                    ticks = [int(v) for v in fields[1:9]]
                    busy, total = busy + sum(ticks) - ticks[3] - ticks[4], total + sum(ticks)
                    found += 1
    except (OSError, ValueError, IndexError):
        return None
    return (busy, total) if found == len(wanted) else None


# What a command runs: a function, or its name "package.module:function", imported when used
Work = Callable | str


def resolve(work: Work | None) -> Callable | None:
    """The function ``work`` names (``"physgnn.training.train:val_loss"``), imported now; a
    function as it is."""
    if work is None or callable(work):
        return work
    module, _, attribute = work.partition(":")
    return getattr(importlib.import_module(module), attribute)


def command(
    name: str,
    run: Work,
    done: Work | None = None,
    before: Work | tuple[Work, ...] | None = None,
    missing: Mapping[str, str] | None = None,
) -> Callable:
    """``main`` of ``python -m physgnn.<name>`` (config ``conf/<name>.yaml``); it returns what
    ``run`` returns (a Hydra sweeper optimises it). ``main.__wrapped__(cfg)`` is the body
    without Hydra (for tests). Before Hydra writes anything, the command line is checked:
    ``before``'s functions (light: the command module imported them), then that it composes
    (:func:`~physgnn.cli.overrides.check_composes`, ``missing``: what to give instead of an
    option a group lacks), then ``before``'s checks given by name; each error one line.
    ``run``, ``done`` and named checks are imported only when needed (module doc)."""

    def main(cfg: DictConfig):
        free_threads()
        try:
            if HydraConfig.initialized():
                check_added_keys(cfg, list(HydraConfig.get().overrides.task), name)
            with sigterm_interrupts():
                result = resolve(run)(cfg)
        except KeyboardInterrupt as err:
            signum = interrupt_signal(err)
            fail(Interrupted(f"{name} interrupted (exit code {128 + signum})", signum))
        except Exception as err:
            if _in_sweep() and not isinstance(err, Interrupted):
                _report_failed_job(err)
                return None
            if isinstance(err, USER_ERRORS):
                fail(err)
            if disk_problem(err):
                fail(disk_error(err))
            raise
        if done is not None:
            print(resolve(done)(result))
        return result

    # Hydra names the job (and its log file) after the module of the task function.
    main.__module__ = f"physgnn.{name}"
    checks = before if isinstance(before, tuple) else (before,) if before else ()
    first = [check for check in checks if callable(check)]
    composes = functools.partial(check_composes, name, missing=missing)
    checks = (*first, composes, *(check for check in checks if not callable(check)))
    return _outputs_checked(
        hydra.main(version_base="1.3", config_path=CONF_DIR, config_name=name)(main), checks, name
    )


# Hydra's flags that print something and exit (help, the config, the shell completion)
PRINTING_FLAGS = ("-h", "--help", "--hydra-help", "-i", "--info", "-c", "--cfg", "-sc")


def prints_only(argv: list[str]) -> bool:
    """``argv`` asks Hydra to print something and run nothing (``--help``, ``--cfg job``): the
    checks given by name (heavy, for a command that runs) are not needed."""
    return any(arg.split("=")[0] in PRINTING_FLAGS + ("--shell-completion",) for arg in argv)


def run_dir_is_hydras(argv: list[str]) -> list[str]:
    """``argv`` with ``hydra.run.dir=X`` added where ``run_dir=X`` is given without it: Hydra's
    own folder is then the run's (else it makes a stray ``runs/<experiment>/<now>/`` with an
    empty log beside the run being trained)."""
    keys = given(argv)
    if "run_dir" in keys and "hydra.run.dir" not in keys:
        return [*argv, f"hydra.run.dir={keys['run_dir'].written}"]
    return argv


def _outputs_checked(
    hydra_main: Callable, before: tuple[Work, ...] = (), name: str = ""
) -> Callable:
    """``hydra_main`` after :func:`check_outputs_env` (command ``name``) and each check of
    ``before`` on the command line (:func:`resolve`; their errors printed as one line; a named
    one not for a command line that only prints: :func:`prints_only`). ``main(argv)`` runs it
    as if ``argv`` followed the command on the command line (default: ``sys.argv[1:]``)."""

    @functools.wraps(hydra_main)
    def main(argv: list[str] | None = None):
        if argv is not None:
            saved, sys.argv[1:] = sys.argv[:], [str(arg) for arg in argv]
            try:
                return main()
            finally:
                sys.argv[:] = saved
        try:
            check_outputs_env(own=OWN_FOLDER.get(name, "paths.outputs"))
            check_quoting(sys.argv[1:])
            for check in before:
                if callable(check) or not prints_only(sys.argv[1:]):
                    resolve(check)(sys.argv[1:])
        except USER_ERRORS as err:
            fail(err)
        sys.argv[1:] = run_dir_is_hydras(sys.argv[1:])
        return hydra_main()

    main.__wrapped__ = hydra_main.__wrapped__  # the body, as documented in :func:`command`
    return main


def _in_sweep() -> bool:
    return HydraConfig.initialized() and HydraConfig.get().mode == RunMode.MULTIRUN


# A failed sweep job's error, in its Hydra folder (``.hydra/``): the sweep's end counts them
JOB_ERROR = "job_error.txt"


def _report_failed_job(err: Exception) -> None:
    """One line for a user error, the traceback for a bug; the sweep goes on. The line is kept
    in the job's folder (:data:`JOB_ERROR`), whichever process or machine ran the job, for the
    end of the sweep to count (:class:`~physgnn.cli.sweeps.AfterSweep`)."""
    if not isinstance(err, USER_ERRORS):
        traceback.print_exception(err)
    print(f"error: {one_line(err)} (this job failed; the sweep goes on)", file=sys.stderr)
    hydra = HydraConfig.get()
    folder = Path(hydra.runtime.output_dir) / (hydra.output_subdir or "")
    write_text(folder / JOB_ERROR, one_line(err) + "\n")
