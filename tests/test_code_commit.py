"""files.code_commit: the commit of the physgnn code that runs, recorded beside a result."""

from __future__ import annotations

import subprocess
from pathlib import Path

from physgnn import files
from physgnn.files import code_commit

ROOT = Path(__file__).resolve().parents[1]


def git(*args: str, cwd: Path = ROOT) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True).stdout.strip()


def test_this_checkouts_commit_with_a_mark_for_changes():
    dirty = git("status", "--porcelain", "--untracked-files=no")
    assert code_commit() == git("rev-parse", "--short=12", "HEAD") + ("+" if dirty else "")


def test_none_outside_a_checkout_of_physgnn(tmp_path, monkeypatch):
    # an installed package: no checkout at all
    installed = tmp_path / "site-packages" / "physgnn"
    installed.mkdir(parents=True)
    monkeypatch.setattr(files, "__file__", str(installed / "files.py"))
    assert code_commit() is None
    # the package inside another project's checkout (a venv in the user's repository)
    git("init", "-q", str(tmp_path), cwd=tmp_path)
    assert git("rev-parse", "--show-toplevel", cwd=installed) == str(tmp_path.resolve())
    assert code_commit() is None


def test_none_without_git(monkeypatch):
    monkeypatch.setenv("PATH", "")
    assert code_commit() is None
