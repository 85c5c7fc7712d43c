"""mkdocs hooks (``hooks:`` in mkdocs.yml) that keep each fact once.

- The site's install and quick-start pages show sections of the README, the repository's front
  page, read when the site is built: links into docs/ become site links, other repository
  files are named as paths.
- Sphinx roles in docstrings (``:class:`~physgnn.x.Y```), which mkdocstrings shows as raw text,
  become code: ``Y`` (``~`` keeps the last name, as Sphinx does).
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# page of the site -> the README sections (their headings) it shows, in order
README_PAGES = {
    "install.md": ["Install", "On a GPU, several GPUs, a SLURM cluster"],
    "quickstart.md": [
        "Quick start: the shipped model in a minute",
        "From nothing to a trained model and a report",
    ],
}
ROLE = re.compile(r":(?:class|mod|func|meth|data|attr|obj|exc):<code>(~?)([^<]*)</code>")
LINK = re.compile(r"\[([^\]]*)\]\(([^)\s]+)\)")


def readme_section(readme: str, heading: str) -> str:
    """The README's section ``## heading``, up to the next ``## `` heading."""
    match = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", readme, re.M | re.S)
    if match is None:
        raise ValueError(f"README.md has no section '## {heading}' (scripts/mkdocs_hooks.py)")
    return f"## {heading}\n{match.group(1)}"


def site_link(match: re.Match) -> str:
    text, target = match.group(1), match.group(2)
    if re.match(r"^[a-z][a-z0-9+.-]*:|#", target):
        return match.group(0)
    if target.startswith("docs/"):
        return f"[{text}]({target.removeprefix('docs/')})"
    return f"`{target}`" if text.strip("`") == target else f"{text} (`{target}`)"


def readme_page(page: str, readme: str) -> str:
    """The Markdown of the site page ``page`` from the README's sections."""
    sections = [readme_section(readme, heading) for heading in README_PAGES[page]]
    text = "".join(sections).replace("## ", "# ", 1)
    return LINK.sub(site_link, text)


def render_roles(html: str) -> str:
    def code(match: re.Match) -> str:
        name = match.group(2).rsplit(".", 1)[-1] if match.group(1) else match.group(2)
        return f"<code>{name}</code>"

    return ROLE.sub(code, html)


def on_page_markdown(markdown, page, **kwargs):
    if page.file.src_uri not in README_PAGES:
        return markdown
    return readme_page(page.file.src_uri, (ROOT / "README.md").read_text(encoding="utf-8"))


def on_page_content(html, page, **kwargs):
    return render_roles(html)
