"""The pages, the scripts and the code speak of the package and the physics, not of its history.

A reader of README.md, docs/, mpi_runs/ or of a ``--help`` text meets no reference to
the tracker that shaped the package ("the issue", "issue 11", "#24"), to its review
("reviewer") or to its past ("main before the second round", "first run, before the
guard", "the former cap", "formerly capped"): such a passage says what the package does
and what was measured, with the conditions of the measurement.  The phrases below are
matched case-insensitively, on word boundaries, so that "issues a warning", "the lead
of a forecast" or an upstream reference such as ``pmodels/mpich#5930`` pass.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HISTORY = {
    "the tracker": r"\bissue\b|\bissues\s+#?\d",
    "an issue number": r"(?<![\w/])#\d+\b",
    "the package's past": r"\bmain before\b|\bfirst run, before\b|\bbefore the guard\b"
                          r"|\b(?:first|second|third) round\b|\bformerly\b|\bformer\b",
    "its review": r"\breviewers?\b",
    "a garbled parenthesis": r"\(standard deviation\)",
}
PATTERN = re.compile("|".join(f"(?P<g{i}>{p})" for i, p in enumerate(HISTORY.values())),
                     re.IGNORECASE)
TEXT_SUFFIXES = {".md", ".py", ".sh", ".sbatch", ".toml", ".txt", ""}


def checked_files() -> list[Path]:
    """README.md, the Markdown pages of docs/, every text file of mpi_runs/, src/**/*.py."""
    docs = [p for p in (ROOT / "docs").rglob("*.md")
            if not {"_build", "generated"} & set(p.relative_to(ROOT).parts)]
    runs = [p for p in (ROOT / "mpi_runs").rglob("*") if p.is_file()
            and p.suffix in TEXT_SUFFIXES]
    return sorted([ROOT / "README.md", *docs, *runs, *(ROOT / "src").rglob("*.py")])


def history_phrases(text: str) -> list[tuple[int, str, str]]:
    """(line, what, the phrase) of every match in ``text``."""
    names = list(HISTORY)
    found = []
    for number, line in enumerate(text.splitlines(), start=1):
        for m in PATTERN.finditer(line):
            group = next(i for i, g in enumerate(m.groups()) if g is not None)
            found.append((number, names[group], m.group(0)))
    return found


def test_the_phrases_are_found_and_false_friends_pass():
    found = history_phrases("as the issue asked\nbefore issue 11\nsee #24\nmain before the "
                            "second round\nthe former 1e5 cap\nmedian 0.2 (standard deviation)\n")
    assert [line for line, _, _ in found] == [1, 2, 3, 4, 4, 5, 6]
    assert history_phrases("rank 0 issues a warning\nthe lead of a forecast, 3 deg\n"
                           "pmodels/mpich#5930\ncolour #1f77b4\n## Heading\n") == []


@pytest.mark.parametrize("path", checked_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_history_in_the_text(path):
    found = history_phrases(path.read_text(errors="replace"))
    assert not found, f"{path.relative_to(ROOT)}: " + "; ".join(
        f"line {line}: {what} ({phrase!r})" for line, what, phrase in found)
