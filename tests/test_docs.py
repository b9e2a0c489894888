"""The user documents stay true and short (issue 42, items 14-16).

README.md is for users: no issue or session numbers, one short paragraph of
measured timings that names the machine and its load, and a command synopsis
whose every option exists. benchmarks/RESULTS.md is a page of current figures
(the dated log lives in benchmarks/results/HISTORY.md), each section with the
command that remakes it. Every local path the two link to exists. The sample's
own README states a measured time, and pyproject.toml's licence is the PEP 639
string (the table form prints setuptools' deprecation banner at every install).
"""

from __future__ import annotations

import re
import tomllib
from datetime import date
from pathlib import Path

import pytest

from saucerfab.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "benchmarks" / "RESULTS.md"
CHANGELOG = ROOT / "CHANGELOG.md"
SAMPLE_README = ROOT / "samples" / "two_reflections" / "README.md"

#: RESULTS.md is one page of current figures: the dated log goes to benchmarks/results/
MAX_RESULTS_LINES = 360  # twelve areas, a table and its command each
#: "one short paragraph" of timings, in words
MAX_TIMING_WORDS = 120
#: the first setuptools that reads `project.license` as an SPDX string (PEP 639)
SETUPTOOLS_FOR_SPDX_LICENSE = (77,)
#: the repository's tracked folders: a backticked path starting with one of them names a file of any checkout
#: (tools/ is not one: .ci/install-tools fills it, and git ignores it)
REPO_FOLDERS = ("saucerfab/", "samples/", "docs/", "benchmarks/", "tests/", "printers/", ".ci/")

#: a measured duration: "59-70 s", "7 min 44 s", "1.5 ms", "2 minutes"
DURATION = re.compile(r"\b\d+(?:[.,]\d+)?(?:\s?-\s?\d+(?:[.,]\d+)?)?\s?(?:ms|s|min|minutes?|seconds?|h)\b")
#: history a user does not need: "issue 18", "session 20's", "sessions 11-19"
HISTORY_REF = re.compile(r"\b(?:issues?|sessions?)\s+\d+", re.IGNORECASE)
#: a markdown link or image target: [text](target)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
#: an inline code span
CODE = re.compile(r"`([^`\n]+)`")


def _text_outside_fences(text: str) -> str:
    """``text`` with every fenced block (```...```) removed."""
    return re.sub(r"^```.*?^```[^\n]*$", "", text, flags=re.MULTILINE | re.DOTALL)


def _paragraphs(text: str) -> list[str]:
    """The prose paragraphs of a markdown text (blank-line separated, fenced blocks left out)."""
    return [p.strip() for p in re.split(r"\n\s*\n", _text_outside_fences(text)) if p.strip()]


def _sections(text: str) -> dict[str, str]:
    """``## `` heading -> the text under it, up to the next ``## `` heading."""
    parts = re.split(r"^## (.+)$", text, flags=re.MULTILINE)
    return {parts[i].strip(): parts[i + 1] for i in range(1, len(parts) - 1, 2)}


def _synopsis(readme: str) -> list[str]:
    """The README's command synopsis: the first fenced block of its "Commands" section, one entry per command.

    A line starting with ``saucerfab`` starts an entry; an indented line continues it.
    """
    body = _sections(readme)["Commands"]
    block = re.search(r"^```[^\n]*\n(.*?)^```", body, flags=re.MULTILINE | re.DOTALL)
    assert block, "README.md's Commands section has no fenced synopsis block"
    entries: list[str] = []
    for line in block.group(1).splitlines():
        line = re.sub(r"\s#\s.*$", "", line)  # a shell comment ('#rrggbb' stays: no blank after its '#')
        if line.startswith("saucerfab"):
            entries.append(line)
        elif line.strip() and entries:
            entries[-1] += " " + line.strip()
    return entries


def _timing_paragraphs(readme: str) -> list[str]:
    """Paragraphs that give measured durations of the README's two commands."""
    return [p for p in _paragraphs(readme)
            if DURATION.search(p) and re.search(r"make (?:demo|test)|\.ci/run", p)]


def _local_targets(doc: Path) -> list[str]:
    """Local paths ``doc`` points to: its markdown links, and backticked paths in the repository's folders."""
    text = doc.read_text(encoding="utf-8")
    found = [t for t in LINK.findall(text) if not re.match(r"[a-z]+:|#", t)]
    for span in CODE.findall(_text_outside_fences(text)):
        token = span.split("::", 1)[0]
        if " " in token or "*" in token or "<" in token or "..." in token:
            continue
        if token.startswith(REPO_FOLDERS) or (doc == RESULTS and token.startswith("results/")):
            found.append(token)
    return found


def _resolve(doc: Path, target: str) -> Path:
    """Where ``target`` in ``doc`` points: relative to the document's folder, a repository path to the root."""
    target = target.split("#", 1)[0]
    near = doc.parent / target
    return near if near.exists() or not target.startswith(REPO_FOLDERS) else ROOT / target


def test_readme_names_no_issue_or_session() -> None:
    """The dated history (issue and session numbers) belongs in git and CHANGELOG.md, not in the README."""
    found = HISTORY_REF.findall(README.read_text(encoding="utf-8"))
    assert not found, f"README.md mentions {found}: move that history to CHANGELOG.md"


def test_readme_timings_are_one_short_paragraph_with_machine_and_load() -> None:
    """One paragraph gives the two commands' measured times, with the machine and its load."""
    timings = _timing_paragraphs(README.read_text(encoding="utf-8"))
    assert len(timings) == 1, f"README.md gives timings of make demo / make test in {len(timings)} paragraphs, not one"
    para = timings[0]
    assert re.search(r"\d+-core", para) and re.search(r"\b(AMD|Intel|Apple|Ampere)\b", para), \
        f"the timing paragraph names no machine (its cores and CPU): {para}"
    assert re.search(r"\bload\b", para), f"the timing paragraph names no load: {para}"
    words = len(para.split())
    assert words <= MAX_TIMING_WORDS, f"the timing paragraph has {words} words, more than {MAX_TIMING_WORDS}"


def test_readme_synopsis_options_exist() -> None:
    """Every ``--option`` of the README's synopsis is an option of the command it is shown with."""
    parser = build_parser()
    subparsers = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    entries = _synopsis(README.read_text(encoding="utf-8"))
    assert len(entries) >= len(subparsers.choices), f"the synopsis shows {len(entries)} commands"
    wrong = []
    for entry in entries:
        words = entry.split()
        command = words[1]
        if command.startswith("--"):  # a top-level option: saucerfab --version
            known = parser._option_string_actions
        else:
            assert command in subparsers.choices, f"the synopsis shows a command saucerfab has not: {command}"
            known = subparsers.choices[command]._option_string_actions
        wrong += [f"{command} {opt}" for opt in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", entry) if opt not in known]
    assert not wrong, f"options the README's synopsis shows but the parser has not: {wrong}"


def test_results_is_one_page_with_a_command_per_section() -> None:
    """RESULTS.md holds the current figures only, each section with the command that remakes them."""
    text = RESULTS.read_text(encoding="utf-8")
    lines = len(text.splitlines())
    assert lines < MAX_RESULTS_LINES, f"benchmarks/RESULTS.md has {lines} lines: move history to benchmarks/results/"
    sections = _sections(text)
    assert sections, "benchmarks/RESULTS.md has no sections"
    for name, body in sections.items():
        fence = re.search(r"^```[^\n]*\n(.+?)^```", body, flags=re.MULTILINE | re.DOTALL)
        assert fence and re.search(r"benchmarks/|saucerfab|make ", fence.group(1)), (
            f"RESULTS.md section '{name}' has no fenced command that remakes its figures")


@pytest.mark.parametrize("doc", [README, RESULTS], ids=["README.md", "RESULTS.md"])
def test_local_paths_exist(doc: Path) -> None:
    """Every local file a document links to, or names by its repository path, exists."""
    missing = [t for t in _local_targets(doc) if not _resolve(doc, t).exists()]
    assert not missing, f"{doc.relative_to(ROOT)} points to files that do not exist: {missing}"


def test_sample_readme_states_a_measured_time() -> None:
    """The two-reflection sample's README gives the time as measured, with the machine's load, not a guess."""
    text = SAMPLE_README.read_text(encoding="utf-8")
    assert not re.search(r"\babout \d+ minutes?\b", text), "samples/two_reflections/README.md guesses its time"
    timed = [p for p in _paragraphs(text) if DURATION.search(p)]
    assert any(re.search(r"\bload\b", p) and re.search(r"\d+-core|\d+ cores", p) for p in timed), (
        "samples/two_reflections/README.md gives no measured time with the machine and its load")


def test_changelog_is_dated_newest_first() -> None:
    """CHANGELOG.md (keep-a-changelog style) holds the dated history, newest first."""
    text = CHANGELOG.read_text(encoding="utf-8")
    dates = [date.fromisoformat(d) for d in re.findall(r"^## .*?(\d{4}-\d{2}-\d{2})", text, flags=re.MULTILINE)]
    assert len(dates) >= 2, "CHANGELOG.md has no dated sections"
    assert dates == sorted(dates, reverse=True), f"CHANGELOG.md's dates are not newest first: {dates}"


def test_pyproject_license_is_an_spdx_string() -> None:
    """PEP 639: ``license = "MIT"`` (a table prints a deprecation banner), with a setuptools that reads it."""
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    licence = pyproject["project"]["license"]
    assert isinstance(licence, str), f"project.license is {licence!r}: write the SPDX string, license = \"MIT\""
    floors = [re.fullmatch(r"setuptools\s*>=\s*([\d.]+)", r) for r in pyproject["build-system"]["requires"]]
    floor = next((tuple(int(x) for x in m.group(1).split(".")) for m in floors if m), ())
    assert floor >= SETUPTOOLS_FOR_SPDX_LICENSE, (
        f"build-system requires setuptools>={'.'.join(map(str, floor))}: the SPDX string needs setuptools>=77")
