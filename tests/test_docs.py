"""The documents: every relative link resolves, every document cited exists, the README is short."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")  # [text](target#anchor)
CITED = re.compile(r"\b((?:docs/)?[\w./-]*[A-Za-z_]\.md)\b")  # a .md file named in text


def test_relative_links_in_the_readme_and_docs_resolve() -> None:
    broken = [
        f"{doc.relative_to(ROOT)}: {target}"
        for doc in DOCS
        for target in LINK.findall(doc.read_text())
        if "://" not in target and not (doc.parent / target).exists()
    ]
    assert not broken, "broken links:\n" + "\n".join(broken)


def test_no_file_cites_a_document_that_is_not_there() -> None:
    """Source, tests and documents name only .md files the repository has (results and
    reports written by the benchmarks are looked up under benchmarks/)."""
    files = [
        *DOCS,
        *ROOT.glob("dpm/**/*.py"),
        *ROOT.glob("tests/*.py"),
        *ROOT.glob("benchmarks/*.py"),
    ]
    known = {p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*.md") if ".venv" not in p.parts}
    names = {Path(k).name for k in known}
    missing = set()
    for path in files:
        for cited in CITED.findall(path.read_text(errors="replace")):
            if cited not in known and Path(cited).name not in names:
                missing.add(f"{path.relative_to(ROOT)}: {cited}")
    assert not missing, "cited but missing:\n" + "\n".join(sorted(missing))


def test_the_readme_is_at_most_200_lines() -> None:
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200
