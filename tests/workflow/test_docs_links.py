"""The user-facing docs name only files that exist: README.md, docs/*.md and config/README.md.

Checked: relative markdown links and images (`[text](path#anchor)`, relative to the page, the
anchor against the target's headings), and repository paths the text names, in backticks or
bare (`docs/x.md`, `workflow/...`, `tests/...`, `kernels/...`, ...: relative to the repository's
root, as the docs write them). A path with a placeholder (`<stage>`, `{scene}`, `$VAR`) is
skipped; one with a glob (`tests/render/test_*mitsuba*.py`) must match at least one file; a
pytest node id or a function after the file (`tests/x.py::test_y`, `stage.py:run`) is checked as
the file.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PAGES = sorted([REPO / "README.md", REPO / "config" / "README.md", *(REPO / "docs").glob("*.md")])
# the repository's top-level folders and files a path in the docs may start with
ROOTS = ("docs/", "workflow/", "tests/", "kernels/", "config/", "envs/", ".ci/")
ROOT_FILES = ("README.md", "Snakefile", "pyproject.toml")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
CODE = re.compile(r"`([^`\n]+)`")
BARE = re.compile(r"(?<![\w/.$-])((?:" + "|".join(re.escape(r) for r in ROOTS) + r")[\w./*-]*[\w*/])")
PLACEHOLDER = re.compile(r"[<>{}$]")
HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$", re.M)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, markup and punctuation dropped, spaces to -."""
    text = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(page: Path) -> set[str]:
    return {slug(h) for h in HEADING.findall(strip_fences(page.read_text(encoding="utf-8")))}


def strip_fences(text: str) -> str:
    """The text without fenced code blocks (commands and trees, checked as paths below)."""
    return re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)


def repo_paths(text: str) -> set[str]:
    """Repository paths named in backticks or bare, as written (trailing punctuation dropped)."""
    found = set()
    for span in CODE.findall(text):
        for token in re.split(r"[\s,;()\"'=]+", span):
            if token.startswith(ROOTS) or token in ROOT_FILES:
                found.add(token)
    found |= set(BARE.findall(text))
    return {normal(path) for path in found}


def normal(path: str) -> str:
    """The file a path names: trailing punctuation, a pytest node id (``::test``) and a function
    after the file (``stage.py:run``) dropped."""
    path = path.split("::")[0].rstrip(".:,;")
    return re.sub(r"(\.\w+):\w+$", r"\1", path)


def missing_path(path: str) -> bool:
    if PLACEHOLDER.search(path):
        return False
    if any(ch in path for ch in "*?["):
        return not any(REPO.glob(path))
    return not (REPO / path).exists()


def broken(page: Path) -> list[str]:
    """What ``page`` names that is not there, one line each."""
    text = page.read_text(encoding="utf-8")
    problems = []
    for target in LINK.findall(strip_fences(text)):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        dest = (page.parent / file).resolve() if file else page
        if not dest.exists():
            problems.append(f"link ({target}): no file {dest.relative_to(REPO) if dest.is_relative_to(REPO) else dest}")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            problems.append(f"link ({target}): no heading with anchor #{anchor}")
    for path in sorted(repo_paths(text)):
        if missing_path(path):
            problems.append(f"path {path}: not in the repository")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_file_the_docs_name_exists(page):
    assert broken(page) == []


def test_the_check_finds_a_missing_file_a_missing_anchor_and_a_missing_path(tmp_path, monkeypatch):
    """The checker itself: what it must report, and what it must let pass."""
    page = tmp_path / "page.md"
    (tmp_path / "there.md").write_text("# A heading\n")
    page.write_text(
        "# Title\n\nSee [it](there.md#a-heading), [up](#title), [web](https://example.org/x.md), "
        "`docs/architecture.md`, `tests/render/test_*.py`, `results/{scene}/capture`, "
        "`tests/test_cli_signals.py::test_x` and workflow/invrender/cli.py.\n\n"
        "Broken: [gone](gone.md), [anchor](there.md#nowhere), `docs/NOT-THERE.md`, "
        "`workflow/rules/nothing.smk:run`, tests/no_such_test.py, `tests/render/test_*nothing*.py`.\n\n"
        "```\ndocs/inside-a-fence.md\n```\n"
    )
    problems = broken(page)
    assert len(problems) == 7, problems
    for name in ("gone.md", "#nowhere", "docs/NOT-THERE.md", "nothing.smk", "no_such_test.py", "test_*nothing*"):
        assert any(name in p for p in problems), name
    assert any("inside-a-fence" in p for p in problems)  # a fenced tree is a path too


def test_headings_become_githubs_anchors():
    assert slug("2. Run the demo") == "2-run-the-demo"
    assert slug("Set up") == "set-up"
    assert slug("The `room` mode's capture") == "the-room-modes-capture"
