"""The user guide says what holds today, and its links land on headings that exist.

The guide pages (``docs/*.md``) carry no measurement dates: the dated record of each
measurement lives in ``docs/validation/``. Every relative link with an anchor, in
``docs/`` and in ``README.md``, points at a heading (or an element id) of its target page,
with the ids the site builder gives them (Python-Markdown's ``toc`` and ``attr_list``).
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

import markdown
import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

_DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")
# a date that is the time window of a data record (a command's --from / --to, a study
# file's start / end), not the date of a measurement
_RECORD_WINDOW = re.compile(r"(--from|--to|\bstart\s*=|\bend\s*=)\s*\"?$")
_FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
_INLINE_CODE = re.compile(r"`[^`\n]*`")
_LINK = re.compile(r"\]\(([^)\s]*)#([^)\s]+)\)")
_ID = re.compile(r"""\bid="([^"]+)\"""")


def _guide_pages() -> list[Path]:
    return sorted(DOCS.glob("*.md"))


def _measurement_dates(text: str) -> list[tuple[int, str]]:
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        for match in _DATE.finditer(line):
            if not _RECORD_WINDOW.search(line[: match.start()]):
                found.append((number, line.strip()))
    return found


def test_the_guide_pages_exist_and_the_logs_are_separate() -> None:
    names = {page.name for page in _guide_pages()}
    assert {"case-studies.md", "benchmarks.md", "index.md"} <= names
    assert (DOCS / "validation" / "case-studies-log.md").is_file()
    assert (DOCS / "validation" / "benchmarks-log.md").is_file()


@pytest.mark.parametrize("page", _guide_pages(), ids=lambda page: page.name)
def test_a_guide_page_holds_no_measurement_date(page: Path) -> None:
    dates = _measurement_dates(page.read_text(encoding="utf-8"))
    assert not dates, (
        f"docs/{page.name} holds dates; the dated record belongs in docs/validation/: "
        + "; ".join(f"line {number}: {line[:100]}" for number, line in dates)
    )


def test_the_date_check_tells_a_record_window_from_a_measurement_date() -> None:
    assert _measurement_dates("Measured 2026-11-27 on the idle machine.")
    assert _measurement_dates("| run | (ran 0.2 s on 2026-11-25 10:30) |")
    assert not _measurement_dates("bayescal predict s --from 2013-02-01 --to 2013-03-01")
    assert not _measurement_dates('end = "2013-09-11"')
    assert not _measurement_dates('end = "2013-09-11T00:00:00"')


@cache
def _ids(page: Path) -> frozenset[str]:
    """The element ids of a page as the site's Markdown extensions render it."""
    md = markdown.Markdown(
        extensions=["toc", "attr_list", "tables", "admonition", "def_list"],
    )
    html = md.convert(page.read_text(encoding="utf-8"))
    return frozenset(_ID.findall(html))


def _anchored_links(page: Path) -> list[tuple[str, str]]:
    text = _INLINE_CODE.sub("", _FENCE.sub("", page.read_text(encoding="utf-8")))
    links = []
    for target, anchor in _LINK.findall(text):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        links.append((target, anchor))
    return links


def _linking_pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]


@pytest.mark.parametrize("page", _linking_pages(), ids=lambda page: str(page.relative_to(ROOT)))
def test_every_anchored_link_lands_on_a_heading(page: Path) -> None:
    broken = []
    for target, anchor in _anchored_links(page):
        path = (page.parent / target).resolve() if target else page
        if not path.is_file():
            broken.append(f"{target}#{anchor}: no such file")
            continue
        if "\n::: " in path.read_text(encoding="utf-8"):
            continue  # an API page: its ids come from mkdocstrings at build time
        if anchor not in _ids(path):
            broken.append(f"{target}#{anchor}: no such heading")
    assert not broken, f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def test_the_link_check_sees_a_broken_anchor(tmp_path: Path) -> None:
    (tmp_path / "a.md").write_text("# A page\n\n## Current results\n", encoding="utf-8")
    assert {"a-page", "current-results"} <= _ids(tmp_path / "a.md")
    (tmp_path / "b.md").write_text(
        "[ok](a.md#current-results) [gone](a.md#results-2026-11-27) `[code](a.md#x)`\n",
        encoding="utf-8",
    )
    assert _anchored_links(tmp_path / "b.md") == [
        ("a.md", "current-results"),
        ("a.md", "results-2026-11-27"),
    ]
