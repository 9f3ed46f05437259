"""The documentation's relative links resolve, and every doc says what kind of doc it is.

Every relative markdown link (``[text](path)``, ``![alt](path)``) in README.md, docs/ and the
benchmarks/ and research/ indexes must name a file or folder of the checkout (the ``#section``
part is not checked). Every page of docs/ says in its first line under the title whether it
describes the product (``*Product guide: ...*``) or records evidence (``*Evidence: ...*``, the
pages of docs/notes/).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(
    [ROOT / "README.md", ROOT / "benchmarks" / "README.md", ROOT / "research" / "README.md"]
    + list(DOCS.rglob("*.md"))
)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^```.*?^```", re.M | re.S)
CODE = re.compile(r"`[^`\n]*`")


def relative_links(text: str) -> list[str]:
    """The link targets of ``text`` outside code, without URLs and in-page anchors."""
    text = CODE.sub("", FENCE.sub("", text))
    return [
        target
        for target in LINK.findall(text)
        if not re.match(r"[a-z][a-z0-9+.-]*:", target) and not target.startswith("#")
    ]


def test_the_link_scan_skips_urls_anchors_and_code():
    text = (
        "[a](x.md) ![b](img/p.png#z) [c](https://e.org) [d](#s) `[e](no.md)`\n```\n[f](no.md)\n```"
    )
    assert relative_links(text) == ["x.md", "img/p.png#z"]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_resolves(page):
    broken = [
        target
        for target in relative_links(page.read_text(encoding="utf-8"))
        if not (page.parent / target.split("#", 1)[0]).exists()
    ]
    assert broken == []


@pytest.mark.parametrize(
    "page", sorted(DOCS.rglob("*.md")), ids=lambda p: p.relative_to(ROOT).as_posix()
)
def test_every_doc_says_whether_it_is_a_product_guide_or_evidence(page):
    lines = [line for line in page.read_text(encoding="utf-8").splitlines() if line.strip()]
    assert lines[0].startswith("# ")
    label = "*Evidence: " if page.parent.name == "notes" else "*Product guide: "
    assert lines[1].startswith(label)
