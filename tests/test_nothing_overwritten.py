"""Nothing of the user's is overwritten, and a mistake is one line naming the key, the value
and the fix: output folders that are files (or lie in one), folders of the user's given to
train, bench, sleep_study and data_report, notebook films, bench switches and sizes, data_report
presets and splits, scores of another scene."""

from __future__ import annotations

import json

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from simdata import trajectory

import physgnn.api as pg
import physgnn.benchmark.run as bench_run
from physgnn import CONF_DIR
from physgnn import bench as bench_command
from physgnn import eval as eval_command
from physgnn import simulate as simulate_command
from physgnn import sleep_study as sleep_study_command
from physgnn import train as train_command
from physgnn.benchmark.source import BenchError
from physgnn.data.dataset import DATASET_MARKER, write_split
from physgnn.errors import ConfigError
from physgnn.evaluation.data_report import DataReportError, data_report
from physgnn.evaluation.sleep_study import study
from physgnn.files import OUTPUT_MARKER, claim_folder, claimed
from physgnn.training.resume_checks import check_run_dir


def _cfg(name: str, *overrides: str):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(name, overrides=list(overrides))


def _error_line(capsys, main, *args: str) -> str:
    """``main(args)``'s one stderr line (exit code 2), nothing before it."""
    with pytest.raises(SystemExit) as info:
        main(list(args))
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err.strip()


def _snapshot(folder) -> dict:
    """Every file under ``folder`` (hidden ones too) with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


@pytest.fixture
def a_file(tmp_path):
    path = tmp_path / "afile.txt"
    path.write_text("mine")
    return path


@pytest.fixture
def mine(tmp_path):
    """A folder of the user's."""
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("my notes")
    return folder


# --- an output folder that is a file, or lies in one -----------------------------------------


@pytest.mark.parametrize(
    "command,key,extra",
    [
        (eval_command, "report_dir", ()),
        (bench_command, "out_dir", ()),
        (sleep_study_command, "out", ("run=x",)),
        (train_command, "run_dir", ("data=tiny",)),
    ],
)
@pytest.mark.parametrize("below", [False, True], ids=["the file", "below the file"])
def test_an_output_folder_that_is_a_file_is_one_line(
    capsys, tmp_path, a_file, command, key, extra, below
):
    folder = a_file / "sub" if below else a_file
    line = _error_line(capsys, command.main, *extra, f"{key}={folder}")
    where = f"lies in {a_file}, a file" if below else "is a file"
    assert line == f"error: {key}={folder} {where}: choose a folder for {key}"
    assert a_file.read_text() == "mine" and sorted(tmp_path.iterdir()) == [a_file]


def test_claim_folder_names_a_file_the_folder_would_lie_in(a_file):
    with pytest.raises(FileExistsError) as err:
        claim_folder(a_file / "sub", "out")
    assert str(err.value) == f"out {a_file / 'sub'} lies in {a_file}, a file: choose another out"
    assert a_file.read_text() == "mine"


# --- train into a folder of the user's -------------------------------------------------------


def test_train_into_a_folder_of_the_users_is_refused_and_leaves_it_as_it_was(
    capsys, tmp_path, mine
):
    before = _snapshot(mine)
    args = ("data=tiny", f"paths.outputs={tmp_path / 'outputs'}", f"run_dir={mine}")
    line = _error_line(capsys, train_command.main, *args)
    assert line == (
        f"error: run_dir {mine} is a folder with files that physgnn did not write (notes.txt; "
        "no run.json): choose another run_dir (a new or empty folder)"
    )
    assert _snapshot(mine) == before and sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine"]  # no lock, no outputs


def test_a_run_folder_before_its_run_json_is_trained_in(tmp_path, mine):
    cfg = OmegaConf.create({})
    check_run_dir(cfg, tmp_path / "new")  # absent
    (tmp_path / "empty").mkdir()
    check_run_dir(cfg, tmp_path / "empty")
    started = tmp_path / "started"  # what Hydra writes there before the training starts
    (started / ".hydra").mkdir(parents=True)
    (started / ".hydra" / "config.yaml").write_text("seed: 0\n")
    (started / "train.log").write_text("")
    check_run_dir(cfg, started)
    (mine / "more.txt").write_text("more")
    with pytest.raises(ConfigError, match=r"\(more.txt and 1 more; no run.json\)"):
        check_run_dir(cfg, mine)


# --- bench ----------------------------------------------------------------------------------


def test_bench_into_a_folder_of_the_users_is_refused_untouched(capsys, mine):
    (mine / "bench.md").write_text("my bench")
    before = _snapshot(mine)
    line = _error_line(capsys, bench_command.main, f"out_dir={mine}", "quick=true")
    assert line == (
        f"error: out_dir {mine} is a folder with files that physgnn did not write (no "
        f"{OUTPUT_MARKER}): choose another out_dir, or pass overwrite=true to write over them"
    )
    assert _snapshot(mine) == before


class Measured(Exception):
    """Raised where the bench starts measuring: its folder was claimed."""


def _measured(*args):
    raise Measured


@pytest.mark.parametrize("default", [True, False], ids=["default out_dir", "overwrite=true"])
def test_bench_writes_its_default_folder_again_and_a_users_with_overwrite(
    tmp_path, monkeypatch, default
):
    monkeypatch.setattr(bench_run.machine, "machine_info", _measured)
    outputs = tmp_path / "outputs"
    folder = outputs / "bench" if default else tmp_path / "mine"
    folder.mkdir(parents=True)
    (folder / "bench.md").write_text("an earlier make bench, before the marker")
    given = [] if default else [f"out_dir={folder}", "overwrite=true"]
    with pytest.raises(Measured):
        bench_run.bench(_cfg("bench", "quick=true", f"paths.outputs={outputs}", *given))
    assert (folder / OUTPUT_MARKER).is_file() == default  # a folder of the user's: unmarked


@pytest.mark.parametrize("key", ["quick", "large", "overwrite"])
@pytest.mark.parametrize("value", ["maybe", "no", "1"])
def test_bench_switches_are_true_or_false(tmp_path, key, value):
    with pytest.raises(BenchError) as err:
        bench_run.bench(_cfg("bench", f"{key}={value}", f"out_dir={tmp_path / 'b'}"))
    shown = repr(int(value)) if value == "1" else repr(value)
    assert str(err.value) == f"{key} must be true or false, got {shown} (e.g. {key}=true)"
    assert not (tmp_path / "b").exists()


@pytest.mark.parametrize(
    "sizes,message",
    [
        ("[-5]", "sizes[0] must be a whole number >= 1 (spheres of a bench scene), got -5"),
        ("[10,0]", "sizes[1] must be a whole number >= 1 (spheres of a bench scene), got 0"),
        ("[2.5]", "sizes[0] must be a whole number >= 1 (spheres of a bench scene), got 2.5"),
        ("10", "sizes must be a list of whole numbers >= 1 (spheres of a bench scene), got 10"),
    ],
)
def test_bench_sizes_are_whole_numbers_of_spheres(tmp_path, sizes, message):
    with pytest.raises(BenchError) as err:
        bench_run.bench(_cfg("bench", f"sizes={sizes}", f"out_dir={tmp_path}"))
    assert str(err.value) == f"{message} (e.g. sizes=[154,1000])"


# --- sleep_study ----------------------------------------------------------------------------


def test_sleep_study_into_a_folder_of_the_users_is_refused_before_the_work(mine):
    (mine / "sleep_study.json").write_text('{"mine": true}')
    before = _snapshot(mine)
    with pytest.raises(FileExistsError) as err:
        study(_cfg("sleep_study", "run=no/such/run", f"out={mine}"))
    assert str(err.value) == (
        f"out {mine} is a folder with files that physgnn did not write (no {OUTPUT_MARKER}): "
        "choose another out"
    )
    assert _snapshot(mine) == before


# --- data_report ----------------------------------------------------------------------------


@pytest.fixture
def splits(tmp_path):
    """A folder of the user's holding a test and an OOD split (no dataset marker)."""
    folder = tmp_path / "splits"
    folder.mkdir()
    traj = trajectory(n=2, frames=6)
    write_split(folder / "test.h5", [traj], {"split": "test", "preset": "hand"})
    write_split(folder / "ood.h5", [traj], {"split": "ood", "preset": "hand"})
    return folder


def test_data_report_never_replaces_a_report_json_of_the_users(splits):
    (splits / "report.json").write_text('{"my": "report"}')
    with pytest.raises(DataReportError) as err:
        data_report(_cfg("data_report", f"dataset={splits}"))
    assert str(err.value) == (
        f"dataset={splits} holds a report.json that physgnn did not write (no "
        f"{DATASET_MARKER} there): move it away, or report a copy of the split files in "
        "another folder"
    )
    assert (splits / "report.json").read_text() == '{"my": "report"}'


def test_data_report_writes_its_own_report_json_again(splits):
    cfg = _cfg("data_report", f"dataset={splits}")
    first = data_report(cfg)  # no report.json yet
    assert data_report(cfg) == first  # its own, written again
    (splits / "report.json").write_text('{"my": "report"}')
    (splits / DATASET_MARKER).write_text(json.dumps({"preset": "hand"}))
    assert data_report(cfg) == json.loads((splits / "report.json").read_text())  # a dataset's


@pytest.mark.parametrize(
    "override,message",
    [
        ("preset=smal", "preset=smal: no 'smal' in conf/data (options: paper, small, tiny)"),
        (
            "splits=test",
            "splits must be a list of split names (train, val, test, ood), got 'test' "
            "(e.g. splits=[test])",
        ),
        (
            "splits=[tst]",
            "splits[0] must be one of train, val, test, ood (a dataset's split files), got "
            "'tst' (e.g. splits=[test,ood])",
        ),
    ],
)
def test_data_report_names_the_preset_or_split_and_the_options(tmp_path, splits, override, message):
    dataset = [] if override.startswith("preset") else [f"dataset={splits}"]
    with pytest.raises(DataReportError) as err:
        data_report(_cfg("data_report", f"paths.outputs={tmp_path}", *dataset, override))
    assert str(err.value) == message
    assert not (splits / "report.json").exists()


# --- the notebook API -----------------------------------------------------------------------


def test_animate_never_replaces_a_film_unless_told(tmp_path):
    truth = trajectory(n=2, frames=4)
    stem = tmp_path / "mine"
    (tmp_path / "mine.mp4").write_bytes(b"my film")
    with pytest.raises(FileExistsError) as err:
        pg.animate(truth, None, stem)
    assert str(err.value) == (
        f"animate: {stem}.mp4 is there already: choose another stem, or pass overwrite=True "
        "to replace it"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.mp4"]
    assert (tmp_path / "mine.mp4").read_bytes() == b"my film"
    files = pg.animate(truth, None, stem, max_frames=2, overwrite=True)
    assert (tmp_path / "mine.gif").is_file() and files["gif"] == f"{stem}.gif"


def test_score_refuses_a_prediction_of_another_scene():
    with pytest.raises(pg.ArgumentError) as err:
        pg.score(trajectory(n=2, frames=6), trajectory(n=4, frames=6))
    assert str(err.value) == (
        "pred has 2 spheres, truth 4: score a prediction of truth's own scene "
        "(roll_out(model, truth))"
    )


# --- a command that fails before it writes leaves no folder -----------------------------------


def test_a_claimed_folder_goes_again_when_the_block_fails_before_writing(tmp_path, mine):
    new = tmp_path / "new"
    with pytest.raises(ValueError), claimed(new, "out"):
        assert (new / OUTPUT_MARKER).is_file()
        raise ValueError("refused")
    assert not new.exists()
    with claimed(new, "out"):  # done: the folder stays, marked
        pass
    assert (new / OUTPUT_MARKER).is_file()
    (new / "report.md").write_text("an earlier run's")
    with pytest.raises(KeyboardInterrupt), claimed(new, "out"):
        raise KeyboardInterrupt
    assert (new / "report.md").read_text() == "an earlier run's"  # it held something: kept
    (mine / "notes.txt").write_text("mine")
    before = _snapshot(mine)
    with pytest.raises(ValueError), claimed(mine, "out", overwrite=True):
        raise ValueError("refused")
    assert _snapshot(mine) == before


def test_a_refused_eval_simulate_or_sleep_study_leaves_no_folder(tmp_path, capsys):
    folder = tmp_path / "report"
    line = _error_line(capsys, eval_command.main, "runs=no/such/run", f"report_dir={folder}")
    assert line.startswith("error: run folder no/such/run does not exist")
    out = tmp_path / "throw"
    line = _error_line(
        capsys, simulate_command.main, "scene=throw", "run=no/such/run", f"out={out}"
    )
    assert "no/such/run" in line
    study_out = tmp_path / "sleep"
    with pytest.raises(Exception, match="no/such/run"):
        study(_cfg("sleep_study", "run=no/such/run", f"out={study_out}"))
    assert not folder.exists() and not out.exists() and not study_out.exists()
