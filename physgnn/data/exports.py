"""Exports written whole: what :func:`physgnn.api.export` checks first and where it writes.

An export folder is written into a staging folder beside it (``.<name>.partial-*``) and moved
in at the end, replacing the previous folder whole: a failure mid-way (a full disk) leaves the
previous export as it was, and a shorter export leaves no stale frame of a longer one. The
folder gets :data:`~physgnn.files.OUTPUT_MARKER` listing its format and files; a folder is
replaced only when it is absent, empty, or holds nothing but such an export's files. Any
other folder (a file of the user's in it, or another command's output) is refused in one
line naming the file and the fix. The folder ends with the user's umask (not the 700 of a
staging folder); a full disk is one line naming the folder; the previous export that an
export killed between its two renames left aside (``.<name>.old-<pid>-*/<name>``) is put back
by the next export there, before anything else. The formats' writers:
:mod:`~physgnn.data.vtk`, :mod:`~physgnn.data.interchange`, :mod:`~physgnn.data.hdf5_export`.
"""

from __future__ import annotations

import errno
import glob
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from physgnn import __version__
from physgnn.errors import PhysgnnError
from physgnn.files import OUTPUT_MARKER, write_json
from physgnn.locks import process_alive
from physgnn.physics.trajectory import FRAME_KEYS, Trajectory


class ExportError(PhysgnnError, ValueError):
    """Trajectories an export cannot write (none, a name twice, values not finite, ...)."""


def check_exportable(trajs: list, what: str) -> list[Trajectory]:
    """``trajs`` once an export of them can be read back: at least one, each a
    :class:`Trajectory` of finite values, no name twice; else :class:`ExportError`."""
    if not trajs:
        raise ExportError(f"{what} of no trajectory: give one Trajectory or a list of them")
    seen = {}
    for i, traj in enumerate(trajs):
        if not isinstance(traj, Trajectory):
            raise ExportError(f"{what}: item {i} is a {type(traj).__name__}, not a Trajectory")
        if traj.name in seen:
            raise ExportError(
                f"{what}: trajectories {seen[traj.name]} and {i} are both named '{traj.name}' "
                f"(a name identifies a trajectory in the files): rename one "
                f"(dataclasses.replace(traj, name=...))"
            )
        seen[traj.name] = i
        _check_finite(traj, what)
    return trajs


def _check_finite(traj: Trajectory, what: str) -> None:
    """A trajectory with NaN or inf (a diverged rollout) is refused, with its finite prefix."""
    bad = {
        key: np.argwhere(~np.isfinite(np.asarray(getattr(traj, key))))
        for key in ("radius", "mass", *FRAME_KEYS)
    }
    bad = {key: where[0] for key, where in bad.items() if len(where)}
    if bad:
        key = min(bad, key=lambda k: bad[k][0] if k in FRAME_KEYS else -1)
        value = np.asarray(getattr(traj, key))[tuple(bad[key])]
        frame = int(bad[key][0]) if key in FRAME_KEYS else 0
        where = f" at frame {frame}" if key in FRAME_KEYS else ""
        fix = f"export its finite frames: traj.truncated({frame})" if frame else "give finite ones"
        raise ExportError(
            f"{what}: trajectory '{traj.name}' holds {value} in {key}{where} (not finite): {fix}"
        )
    if not np.isfinite(traj.dt) or traj.dt <= 0:
        raise ExportError(f"{what}: trajectory '{traj.name}' has dt {traj.dt}: give dt > 0")


@contextmanager
def staged_folder(folder: str | Path, fmt: str) -> Iterator[Path]:
    """Yield an empty staging folder to write an export of format ``fmt`` into; at the end it
    replaces ``folder`` whole (module doc). Refuses a folder it may not replace
    (:class:`FileExistsError`, one line) before anything is written; a full disk is an
    :class:`ExportDiskFull` naming ``folder``, the staging folder removed."""
    folder = check_folder(folder)
    _restore_set_aside(folder)
    check_replaceable(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    _remove_leftovers(folder)
    staging = None
    try:
        staging = _beside(folder, "partial")
        os.chmod(staging, 0o777 & ~umask())
        yield staging
        files = sorted(p.name for p in staging.iterdir())
        marker = {"physgnn_version": __version__, "export": fmt, "files": files}
        write_json(staging / OUTPUT_MARKER, marker)
        _move_in(staging, folder)
    except OSError as err:
        if not disk_full(err):
            raise
        raise ExportDiskFull(folder, fmt) from None
    finally:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)


class ExportDiskFull(ExportError, OSError):
    """An export that ran out of disk space (also an ``OSError`` with ``errno`` ENOSPC)."""

    def __init__(self, folder: Path, fmt: str):
        try:
            free = f"{shutil.disk_usage(folder.parent).free / 2**20:.1f} MiB free there"
        except OSError:
            free = "the disk is full"
        super().__init__(
            f"export to {fmt}: No space left on device writing {folder} ({free}); "
            f"nothing was changed there: free space, or export into a folder on another disk"
        )
        self.errno = errno.ENOSPC


# What h5py says when a write hit a full disk (its OSError carries no errno then).
DISK_FULL_WORDS = ("No space left on device", "Disk quota exceeded", "errno = 28")


def disk_full(err: OSError) -> bool:
    """``err`` is a full disk or quota (an errno, or h5py's words for one)."""
    if err.errno in (errno.ENOSPC, errno.EDQUOT):
        return True
    return err.errno is None and any(word in str(err) for word in DISK_FULL_WORDS)


def umask() -> int:
    """This process's umask (read without changing it where Linux tells it)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def check_folder(folder) -> Path:
    """``folder`` as a :class:`Path` once it names a folder of its own (not ``''``, ``'.'``,
    ``'..'`` or ``'/'``: an export replaces its folder whole), else :class:`ExportError`."""
    if not isinstance(folder, str | os.PathLike):
        raise ExportError(
            f"export folder must be a folder's path (str or Path), got {type(folder).__name__}"
        )
    path = Path(folder)
    if path.name in ("", ".."):
        raise ExportError(
            f"export folder {str(folder)!r} names no folder of its own (an export replaces its "
            f"folder whole): give a new folder's name, e.g. 'out'"
        )
    return path


def check_replaceable(folder: Path) -> None:
    """``folder`` is absent, empty, or an earlier export's with nothing else in it."""
    if folder.exists() and not folder.is_dir():
        raise FileExistsError(f"export folder {folder} is a file: choose a folder's name")
    if not folder.exists():
        return
    marker = export_marker(folder)
    ours = set(marker.get("files", [])) | ({OUTPUT_MARKER} if marker else set())
    others = sorted(p.name for p in folder.iterdir() if p.name not in ours)
    if others:
        more = f" (and {len(others) - 1} more)" if len(others) > 1 else ""
        raise FileExistsError(
            f"export folder {folder} holds {others[0]}{more}, which no export wrote there: "
            f"export into a new or empty folder, or move those files away"
        )


def export_marker(folder: Path) -> dict:
    """The marker of an export folder (its ``export`` format and ``files``), else {}."""
    try:
        marker = json.loads((Path(folder) / OUTPUT_MARKER).read_text())
    except (OSError, ValueError):
        return {}
    return marker if isinstance(marker, dict) and "export" in marker else {}


def _move_in(staging: Path, folder: Path) -> None:
    """``staging`` renamed to ``folder``; a previous ``folder`` is moved aside first, then
    removed (renames only: nothing there is rewritten in place)."""
    if not folder.exists():
        os.replace(staging, folder)
        return
    aside = _beside(folder, "old")
    try:
        os.replace(folder, aside / folder.name)
        try:
            os.replace(staging, folder)
        except BaseException:  # the earlier export back in place, never removed with aside
            os.replace(aside / folder.name, folder)
            raise
    finally:
        shutil.rmtree(aside, ignore_errors=True)


def _beside(folder: Path, kind: str) -> Path:
    """A new hidden folder ``.<name>.<kind>-<pid>-<random>`` beside ``folder``."""
    prefix = f".{folder.name}.{kind}-{os.getpid()}-"
    return Path(tempfile.mkdtemp(prefix=prefix, dir=folder.parent))


def _leftovers(folder: Path, kind: str) -> list[Path]:
    """The ``kind`` (``partial``, ``old``) folders beside ``folder`` of exports whose process
    died (killed mid-way), newest first."""
    found = []
    for path in folder.parent.glob(f".{glob.escape(folder.name)}.{kind}-*-*"):
        pid = path.name[len(f".{folder.name}.{kind}-") :].split("-")[0]
        if pid.isdigit() and int(pid) != os.getpid() and not process_alive(int(pid)):
            found.append(path)
    return sorted(found, key=_modified, reverse=True)


def _modified(path: Path) -> float:
    """When ``path`` last changed (0 once it is gone: another export removed it)."""
    try:
        return path.stat().st_mtime
    except OSError:
        return 0.0


def _restore_set_aside(folder: Path) -> None:
    """An export killed between its two renames left ``folder`` missing and the previous
    export in ``.<name>.old-<pid>-*/<name>``: that export goes back to ``folder``."""
    if folder.exists() or folder.is_symlink():
        return
    for aside in _leftovers(folder, "old"):
        if (aside / folder.name).is_dir():
            os.replace(aside / folder.name, folder)
            shutil.rmtree(aside, ignore_errors=True)
            return


def _remove_leftovers(folder: Path) -> None:
    """The staging and set-aside folders of exports whose process died; a set-aside export
    is only removed once ``folder`` holds an export (:func:`_restore_set_aside`)."""
    for kind in ("partial", "old"):
        for path in _leftovers(folder, kind):
            shutil.rmtree(path, ignore_errors=True)
