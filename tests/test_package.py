"""The package as a researcher installs it: the console script, the configs and example scenes
inside the wheel, and (slow) a wheel installed into a fresh venv that generates, trains and
simulates from another folder."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest
import tomllib
from setuptools import find_packages

import physgnn
from physgnn.__main__ import COMMANDS
from physgnn.__main__ import main as physgnn_main
from physgnn.groundtruth.scenefile import load_scene, scene_file
from physgnn.physics.scene import SceneError

ROOT = Path(__file__).resolve().parents[1]


def test_every_subpackage_is_in_the_wheel_list():
    listed = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    found = find_packages(str(ROOT), include=["physgnn*"])
    conf = ROOT / "conf"  # data folders: each config group, the shipped weights
    groups = [".".join(p.relative_to(conf).parts) for p in conf.rglob("*") if any(p.glob("*.yaml"))]
    data = [
        "physgnn.conf",
        *(f"physgnn.conf.{g}" for g in groups),
        "physgnn.pretrained",
        "physgnn.pretrained.checkpoints",
    ]
    assert sorted(listed) == sorted([*found, *data])


def test_a_checkout_reads_its_top_level_conf():
    assert Path(physgnn.CONF_DIR) == ROOT / "conf"
    assert Path(physgnn.SCENES_DIR) == ROOT / "conf" / "scene"


def test_an_example_scene_is_found_by_its_name():
    assert scene_file("throw") == ROOT / "conf" / "scene" / "throw.yaml"
    assert load_scene("throw.yaml").name == load_scene(ROOT / "conf/scene/throw.yaml").name
    with pytest.raises(SceneError, match="does not exist;.*\\(head_on, throw, tilted_drop\\)"):
        scene_file("no_such_scene")
    with pytest.raises(SceneError, match="does not exist"):  # a scene family, not a file
        scene_file("random_box")


def test_the_console_script_lists_its_commands(capsys):
    assert physgnn_main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in ("train", "generate", "eval", "simulate", "study", "bench", "ship"):
        assert f"  {name} " in out


def test_an_unknown_command_is_one_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        physgnn_main(["trian"])
    assert exit_.value.code == 2
    assert capsys.readouterr().err.startswith("error: unknown command 'trian'; choose one of")


@pytest.mark.parametrize("name", ["simulate", "ship", "train"])
def test_every_kind_of_command_answers_help(name, monkeypatch, capsys):
    """simulate (own arguments), ship (positional) and a Hydra app; the others are Hydra apps
    like train (the slow wheel test asks each of them)."""
    monkeypatch.setattr(sys, "argv", sys.argv[:])
    with pytest.raises(SystemExit) as exit_:
        physgnn_main([name, "--help"])
    assert exit_.value.code in (0, None)
    assert capsys.readouterr().out.strip()


def test_every_command_is_the_python_m_module_of_its_name():
    """``physgnn X`` runs ``python -m physgnn.X`` (``data-report``: ``physgnn.data_report``),
    as the README says: ``ship`` too."""
    for name, (module, _) in COMMANDS.items():
        assert module == f"physgnn.{name.replace('-', '_')}", name
        assert (ROOT / "physgnn" / f"{module.split('.')[1]}.py").is_file(), module


def test_python_m_physgnn_ship_answers_help_and_usage():
    run = [sys.executable, "-m", "physgnn.ship"]
    helped = subprocess.run([*run, "--help"], capture_output=True, text=True, cwd=ROOT)
    assert helped.returncode == 0 and "physgnn ship" in helped.stdout
    assert "training.export RUN_DIR" not in helped.stdout
    bare = subprocess.run(run, capture_output=True, text=True, cwd=ROOT)
    assert bare.returncode == 2 and bare.stdout.startswith("usage: physgnn ship RUN_DIR")


# What a command imports only to do its work: a second and more each (torch_geometric pulls in
# torch._dynamo), never paid by --help or a mistyped key.
HEAVY = ("torch", "torch_geometric", "lightning", "pybullet")


def _imported(argv: list[str]) -> tuple[subprocess.CompletedProcess, set[str]]:
    """``python -X importtime -m <argv>``, and the top-level modules it imported."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", *argv],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
    )
    lines = [line for line in done.stderr.splitlines() if line.startswith("import time:")]
    names = {line.rsplit("|", 1)[1].strip().split(".")[0] for line in lines}
    done.stderr = "\n".join(line for line in done.stderr.splitlines() if line not in lines)
    return done, names


@pytest.mark.parametrize("name", [n for n in COMMANDS if n != "ship"])
def test_a_mistyped_key_is_one_line_before_any_heavy_import(name):
    done, names = _imported(["physgnn", name, "nonexistent_key=1"])
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip() == (
        f"error: nonexistent_key=1: nonexistent_key is not a key of the "
        f"{name.replace('-', '_')} config"
    )
    assert not names & set(HEAVY), sorted(names & set(HEAVY))


@pytest.mark.parametrize(
    "argv",
    [
        ["physgnn.train", "--help"],
        ["physgnn.train", "model.nonexistent=3"],
        ["physgnn.ship", "--help"],
        ["physgnn", "--version"],
        ["physgnn", "simulate", "--help"],
    ],
    ids=" ".join,
)
def test_help_version_and_a_refused_override_import_nothing_heavy(argv):
    done, names = _imported(argv)
    assert done.returncode in (0, 2), done.stderr
    assert not names & set(HEAVY), sorted(names & set(HEAVY))


def test_a_key_without_its_plus_is_one_line_with_the_closest_key(monkeypatch, capsys):
    """``trainer.max_epoch=1`` (an ``s`` short): not Hydra's "Could not override" of five
    lines, one line naming the closest key."""
    monkeypatch.setattr(sys, "argv", sys.argv[:])
    with pytest.raises(SystemExit) as exit_:
        physgnn_main(["train", "trainer.max_epoch=1"])
    assert exit_.value.code == 2
    assert capsys.readouterr().err.strip() == (
        "error: trainer.max_epoch=1: trainer.max_epoch is not a key of the train config: did "
        "you mean trainer.max_epochs?"
    )


# Left out of the copy a wheel is built from: outputs, environments and build leftovers (a
# stale build/lib would put files into the wheel that the checkout no longer has).
NOT_SOURCES = shutil.ignore_patterns(
    ".git",
    ".venv",
    "outputs",
    "build",
    "dist",
    "*.egg-info",
    "__pycache__",
    ".*_cache",
    ".hypothesis",
)


def _wheel(tmp: Path) -> Path:
    """The wheel built from a clean copy of this checkout (no build isolation: offline; the
    checkout itself gets no build/ folder)."""
    source = tmp / "source"
    shutil.copytree(ROOT, source, ignore=NOT_SOURCES)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "-q",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            str(tmp),
            str(source),
        ],
        check=True,
    )
    (wheel,) = tmp.glob("physgnn-*.whl")
    return wheel


def _fresh_venv(folder: Path) -> Path:
    """A new venv whose own site-packages comes first and which sees this interpreter's
    installed dependencies through a ``.pth`` file (nothing downloaded; physgnn itself only
    from the wheel: the dependencies' folder is a plain path, so no editable hook runs)."""
    subprocess.run([sys.executable, "-m", "venv", str(folder)], check=True)
    python = folder / "bin" / "python"
    ask = "import sysconfig; print(sysconfig.get_path('purelib'))"
    purelib = subprocess.run([python, "-c", ask], capture_output=True, text=True, check=True)
    purelib = purelib.stdout.strip()
    deps = {sysconfig.get_path("purelib"), sysconfig.get_path("platlib")}
    (Path(purelib) / "physgnn_test_deps.pth").write_text("\n".join(sorted(deps)) + "\n")
    return python


@pytest.mark.slow
def test_the_wheel_generates_trains_and_simulates_from_another_folder(tmp_path):
    wheel = _wheel(tmp_path / "dist")
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
    assert {
        "physgnn/conf/train.yaml",
        "physgnn/conf/scene/throw.yaml",
        "physgnn/py.typed",
    } <= names
    python = _fresh_venv(tmp_path / "venv")
    subprocess.run([python, "-m", "pip", "install", "-q", "--no-deps", str(wheel)], check=True)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    script = tmp_path / "venv" / "bin" / "physgnn"

    def run(*args: str) -> str:
        out = subprocess.run(
            [str(a) for a in args], cwd=elsewhere, capture_output=True, text=True, timeout=600
        )
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout

    where = run(python, "-c", "import physgnn; print(physgnn.CONF_DIR)").strip()
    assert where.startswith(str(tmp_path / "venv")) and where.endswith("physgnn/conf")
    for name in COMMANDS:
        assert run(script, name, "--help").strip(), name
    out = elsewhere / "outputs"
    run(script, "generate", "data=tiny", "workers=1", "progress=false")
    run(
        script,
        "train",
        "data=tiny",
        "model.network.M=1",
        "model.network.hidden=16",
        "trainer.max_epochs=1",
        "datamodule.pairs_per_epoch=8",
        "datamodule.batch_size=8",
        "run_dir=outputs/runs/one",
        "trainer.enable_progress_bar=false",
    )
    assert (out / "runs" / "one" / "run.json").is_file()
    run(
        python,
        "-m",
        "physgnn.simulate",
        "scene=throw",
        "run=outputs/runs/one",
        "frames=8",
        "video=false",
        "out=sim",
    )
    assert (elsewhere / "sim" / "simulate.h5").is_file()
    assert (out / "data" / "tiny" / "train.h5").is_file()
