"""``simulate compile=true`` under fault, with a compile that fails as inductor does (no real
compile here): a corrupt cache or a full one is one line naming ``paths.compile_cache`` and how
to clear it; a full one keeps none of this compile's files; the note that a second call loads
the graphs from the cache is printed only when the cache was empty."""

from __future__ import annotations

import errno
import itertools

import pytest
from fakeruns import Falling
from omegaconf import OmegaConf
from simdata import trajectory

import physgnn.evaluation.simulate_learned as S


@pytest.fixture
def fake_run(tmp_path, monkeypatch):
    run = tmp_path / "run"
    run.mkdir()
    monkeypatch.setattr(S, "load_run", lambda folder: (Falling(), OmegaConf.create({}), {}))
    return run


def compile_that(raise_: BaseException | None, writes: str | None = None):
    def compile_simulator(simulator, cache_dir):
        if writes:
            (S.Path(cache_dir) / writes).parent.mkdir(parents=True, exist_ok=True)
            (S.Path(cache_dir) / writes).write_bytes(b"\x7fELF half")
        if raise_ is not None:
            raise raise_

    return compile_simulator


def test_a_corrupt_cache_is_named_with_how_to_clear_it(fake_run, tmp_path, monkeypatch):
    cache = tmp_path / "cache"
    (cache / "ab").mkdir(parents=True)
    (cache / "ab" / "kernel.so").write_bytes(b"\x7fELF")  # truncated
    broken = ImportError(f"{cache}/ab/kernel.so: file too short\n(1 400 lines of C++ follow)")
    monkeypatch.setattr(S, "compile_simulator", compile_that(broken))
    with pytest.raises(S.SimulateError) as err:
        S.learned(str(fake_run), trajectory(n=2, frames=6), compile_cache=str(cache))
    assert str(err.value) == (
        f"compiling the learned step failed (ImportError: {cache}/ab/kernel.so: file too short; "
        f"(1 400 lines of C++ follow)); the compile cache paths.compile_cache={cache} may be "
        f"corrupt (truncated files): clear it (rm -r {cache}) and run again, or run with "
        "compile=false"
    )


@pytest.mark.parametrize(
    "failure",
    [
        OSError(errno.ENOSPC, "No space left on device"),
        RuntimeError("backend='inductor' raised: OSError: [Errno 28] No space left on device"),
    ],
    ids=["oserror", "wrapped"],
)
def test_a_full_cache_is_named_and_this_compiles_files_removed(
    fake_run, tmp_path, monkeypatch, failure
):
    cache = tmp_path / "cache"
    (cache / "old").mkdir(parents=True)
    (cache / "old" / "graph.py").write_text("kept")  # an earlier compile's
    monkeypatch.setattr(S, "compile_simulator", compile_that(failure, writes="new/part.so"))
    with pytest.raises(S.SimulateError) as err:
        S.learned(str(fake_run), trajectory(n=2, frames=6), compile_cache=str(cache))
    reason = "No space left on device" if isinstance(failure, OSError) else "disk full or read-only"
    assert str(err.value) == (
        f"paths.compile_cache={cache} cannot be written ({reason}; what this compile wrote there "
        "was removed): free space there, or choose a writable paths.compile_cache (or "
        "compile=false)"
    )
    assert sorted(p.relative_to(cache).as_posix() for p in cache.rglob("*")) == [
        "old",
        "old/graph.py",
    ]


@pytest.mark.parametrize("empty", [True, False])
def test_the_second_call_note_only_when_the_cache_was_empty(
    fake_run, tmp_path, monkeypatch, capsys, empty
):
    cache = tmp_path / "cache"
    cache.mkdir()
    if not empty:
        (cache / "graph.py").write_text("an earlier compile's")
    monkeypatch.setattr(S, "compile_simulator", compile_that(None))
    counts = itertools.count(0, 3)  # 3 more graphs while the timed rollout ran
    monkeypatch.setattr(S, "compiled_graphs", lambda: next(counts))
    S.learned(str(fake_run), trajectory(n=2, frames=6), compile_cache=str(cache))
    assert ("a second call loads them" in capsys.readouterr().err) == empty
