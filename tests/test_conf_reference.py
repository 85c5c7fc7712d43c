"""docs/configuration.md is the configuration reference generated from conf/ by
scripts/conf_reference.py: the committed page is current, and the reader pairs each key with
its value and its comments."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SPEC = importlib.util.spec_from_file_location("conf_reference", ROOT / "scripts/conf_reference.py")
conf_reference = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(conf_reference)


def test_the_committed_page_is_current():
    committed = (ROOT / "docs" / "configuration.md").read_text(encoding="utf-8")
    assert committed == conf_reference.page(), (
        "docs/configuration.md is stale: python scripts/conf_reference.py > docs/configuration.md"
    )


def test_keys_get_their_value_and_the_comments_above_and_beside_them():
    text = (
        "# what the file is\n"
        "\n"
        "# and how to run it\n"
        "seed: 0\n"
        "lit:\n"
        "  # the noise\n"
        "  # in normalised units\n"
        "  noise_std: 0.03  # 0.03, not 0.01\n"
        "  sizes:\n"
        "    - 1\n"
        "    - 2\n"
        "  name: 'a # b'\n"
        "# not about top: a blank line follows\n"
        "\n"
        "top: 1\n"
    )
    intro, rows = conf_reference.rows(text)
    assert intro == "what the file is and how to run it"
    assert rows == [
        ("seed", "0", ""),
        ("lit", "", ""),
        ("lit.noise_std", "0.03", "the noise in normalised units 0.03, not 0.01"),
        ("lit.sizes", "[1, 2]", ""),
        ("lit.name", "'a # b'", ""),
        ("top", "1", ""),
    ]
