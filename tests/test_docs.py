"""The documentation: every relative link of README.md and docs/**/*.md reaches a file (and, for
a ``#anchor`` into a Markdown page, a heading of it); the README stays short; and, when mkdocs
is installed (the ``docs`` extra), the site builds with ``mkdocs build --strict`` (slow)."""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import re
import shutil
import subprocess
import sys
import unicodedata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HOOKS = importlib.util.spec_from_file_location("mkdocs_hooks", ROOT / "scripts/mkdocs_hooks.py")
mkdocs_hooks = importlib.util.module_from_spec(HOOKS)  # mkdocs loads the hooks by path too
HOOKS.loader.exec_module(mkdocs_hooks)
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
# [text](target) and ![alt](target), not inside code; <a href> is not used in these pages
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
CODE = re.compile(r"`[^`\n]*`")


def strip_code(text: str) -> str:
    """``text`` without fenced blocks and inline code (links there are examples, not links)."""
    return CODE.sub("", FENCE.sub("", text))


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = CODE.sub(lambda m: m.group(0)[1:-1], heading.strip()).lower()
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    kept = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return kept.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """The anchors of ``page``'s headings (repeated headings get -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    found = set()
    for line in FENCE.sub("", page.read_text(encoding="utf-8")).splitlines():
        match = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not match:
            continue
        base = slug(match.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        found.add(base if n == 0 else f"{base}-{n}")
    return found


def broken_links(page: Path, root: Path = ROOT) -> list[str]:
    """``page``'s relative links whose file (or heading) does not exist, or that leave ``root``,
    one line each."""
    problems = []
    for target in LINK.findall(strip_code(page.read_text(encoding="utf-8"))):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # https:, mailto:, ...
            continue
        path, _, anchor = target.partition("#")
        if path.startswith("/"):
            problems.append(f"{page.relative_to(root)}: absolute link {target}")
            continue
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            problems.append(f"{page.relative_to(root)}: {target} (no such file)")
        elif root not in file.parents:
            problems.append(f"{page.relative_to(root)}: {target} (outside the repository)")
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            problems.append(f"{page.relative_to(root)}: {target} (no such heading)")
    return problems


def test_the_checker_finds_broken_links(tmp_path):
    (tmp_path / "other.md").write_text("# A page\n\n## Two words\n", encoding="utf-8")
    page = tmp_path / "page.md"
    page.write_text(
        "[ok](other.md) [ok](other.md#two-words) [web](https://example.org) [self](#here)\n"
        "# Here\n`[code](missing.md)`\n```\n[fenced](missing.md)\n```\n"
        "[gone](missing.md) [bad anchor](other.md#nope) ![img](pic.png)\n",
        encoding="utf-8",
    )
    assert broken_links(page, tmp_path) == [
        "page.md: missing.md (no such file)",
        "page.md: other.md#nope (no such heading)",
        "page.md: pic.png (no such file)",
    ]


def test_no_broken_relative_link():
    problems = [line for page in PAGES for line in broken_links(page)]
    assert not problems, "broken links:\n" + "\n".join(problems)


def test_readme_is_short_and_names_no_machine_path():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 250
    for page in PAGES:
        body = page.read_text(encoding="utf-8")
        assert "/work/" not in body and "/home/" not in body, page


def test_the_site_shows_sphinx_roles_as_code():
    html = (
        "<p>see :class:<code>~physgnn.physics.trajectory.Trajectory</code> and "
        ":func:<code>roll_out</code>, :mod:<code>physgnn.data.exports</code></p>"
    )
    assert mkdocs_hooks.render_roles(html) == (
        "<p>see <code>Trajectory</code> and <code>roll_out</code>, "
        "<code>physgnn.data.exports</code></p>"
    )


def test_the_site_pages_from_the_readme_link_within_the_site():
    readme = (
        "# physgnn\n\n## Install\n\nRead [Model](docs/MODEL.md), [below](#on-a-gpu), "
        "[the weights](physgnn/pretrained/README.md), [`LICENSE`](LICENSE), "
        "[web](https://pyg.org).\n\n## On a GPU\n\nMore.\n\n## Results\n\nNot here.\n"
    )
    pages = {"install.md": ["Install", "On a GPU"]}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(mkdocs_hooks, "README_PAGES", pages)
        page = mkdocs_hooks.readme_page("install.md", readme)
    assert page == (
        "# Install\n\nRead [Model](MODEL.md), [below](#on-a-gpu), the weights "
        "(`physgnn/pretrained/README.md`), `LICENSE`, [web](https://pyg.org).\n\n"
        "## On a GPU\n\nMore.\n\n"
    )


def test_every_readme_section_the_site_shows_exists():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    for page in mkdocs_hooks.README_PAGES:
        assert mkdocs_hooks.readme_page(page, readme).startswith("# ")


def reference_docstrings() -> dict[str, str]:
    """The docstrings the API reference (docs/reference/api.md) shows: each ``::: module``'s
    and its public functions', classes' and their methods', by name."""
    found = {}
    page = (ROOT / "docs" / "reference" / "api.md").read_text(encoding="utf-8")
    for name in re.findall(r"^::: (\S+)", page, re.M):
        module = importlib.import_module(name)
        found[name] = inspect.getdoc(module) or ""
        for key, value in vars(module).items():
            if key.startswith("_") or getattr(value, "__module__", None) != name:
                continue
            found[f"{name}.{key}"] = inspect.getdoc(value) or ""
            for member, inner in vars(value).items() if inspect.isclass(value) else ():
                if not member.startswith("_") and callable(inner):
                    found[f"{name}.{key}.{member}"] = inspect.getdoc(inner) or ""
    return found


def test_the_api_reference_shows_no_restructuredtext_literal_marker():
    # mkdocstrings renders Markdown: a reST "::" before a code block shows as a stray "::"
    for name, doc in reference_docstrings().items():
        marked = [line for line in doc.splitlines() if line.rstrip().endswith("::")]
        assert not marked, f"{name}: {marked} (use a fenced ```python block)"


@pytest.mark.slow
def test_mkdocs_build_strict(tmp_path):
    mkdocs = shutil.which("mkdocs", path=str(Path(sys.executable).parent)) or shutil.which("mkdocs")
    if mkdocs is None:
        pytest.skip("mkdocs is not installed (pip install -e '.[docs]')")
    pytest.importorskip("mkdocstrings_handlers.python", reason="mkdocstrings[python] is missing")
    done = subprocess.run(
        [mkdocs, "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert (tmp_path / "site" / "index.html").exists()


def test_the_headline_results_page_measures_todays_default():
    # docs/index.md's headline page names the fingerprint of the default it measures
    # (physgnn.ablation.jobs.current_fingerprint): a new default fails here until its page is
    # the headline
    from physgnn.ablation.jobs import current_fingerprint

    index = (ROOT / "docs/index.md").read_text(encoding="utf-8")
    target = re.search(r"\[the default model's results\]\(([^)]+)\)", index)
    assert target, "docs/index.md names no headline results page"
    page = (ROOT / "docs" / target.group(1)).read_text(encoding="utf-8")
    assert current_fingerprint() in page


def test_the_module_cap_the_docs_state_is_the_one_the_architecture_test_holds():
    caps = (ROOT / "tests/test_architecture.py").read_text(encoding="utf-8")
    module, function = (
        int(re.search(rf"^MAX_{what}_LINES = (\d+)", caps, re.M).group(1))
        for what in ("MODULE", "FUNCTION")
    )
    architecture = (ROOT / "docs/ARCHITECTURE.md").read_text(encoding="utf-8")
    rule = re.search(
        r"^6\. Modules of at most (\d+) lines, functions of at most (\d+)\.", architecture, re.M
    )
    assert rule and (int(rule.group(1)), int(rule.group(2))) == (module, function)
