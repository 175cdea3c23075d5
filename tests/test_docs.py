"""The user documents: README's length, no journal words, README's figures the same as the docs it links.

The docs describe the tool as it is (its history is in git), and a figure README quotes is the
figure of the document it links for the same quantity.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
DOCS = REPO / "docs"
README_MAX_LINES = 250

#: User documents: what a user reads on the repository's pages.
USER_DOCS = sorted([README, REPO / "samples" / "README.md", *DOCS.glob("*.md")])

#: Journal words: a document that tells when or in which issue something changed instead of what is.
JOURNAL = [
    re.compile(r"\bissues?[\s-]*#?\d+", re.I),                  # "Issue 27: ...", "since issue 31", "issue-13"
    re.compile(r"\b(?:this|last|the previous|the next|that|earlier|each)\s+(?:stop|session)s?\b", re.I),
]
#: Another project's tracker is a citation, not a journal entry ("pyGeo issue 7").
OTHER_TRACKERS = re.compile(r"\b(?:pyGeo|SU2|OpenMDAO|meshio|numba|scipy|NumPy|IDWarp|pySpline|OpenFOAM)"
                            r"(?:'s)?\s+issues?\s*#?\d+", re.I)


def journal_words(text: str) -> list[str]:
    """The journal phrases of ``text`` (with their line numbers), other projects' issues left out."""
    found = []
    for n, line in enumerate(text.splitlines(), 1):
        line = OTHER_TRACKERS.sub("", line)
        found += [f"line {n}: {m.group(0)!r}" for rx in JOURNAL for m in rx.finditer(line)]
    return found


def printed_benchmark_texts() -> dict[str, str]:
    """What ``make bench`` prints of each ``benchmarks/bench_*.py``: its TITLE and NOTES, read with ast."""
    out = {}
    for path in sorted((REPO / "benchmarks").glob("bench_*.py")):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Assign) and any(getattr(t, "id", "") in ("TITLE", "NOTES") for t in node.targets):
                try:
                    value = ast.literal_eval(node.value)
                except ValueError:              # an f-string: its constant parts
                    value = " ".join(c.value for c in ast.walk(node.value)
                                     if isinstance(c, ast.Constant) and isinstance(c.value, str))
                out[f"{path.name}:{node.targets[0].id}"] = value
    return out


def package_docstrings() -> dict[str, str]:
    """Every module, class and function docstring of ``ffdcli`` (what ``help()`` shows a user)."""
    out = {}
    for path in sorted((REPO / "ffdcli").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in [tree, *ast.walk(tree)]:
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                doc = ast.get_docstring(node, clean=False)
                if doc:
                    out[f"{path.relative_to(REPO)}:{getattr(node, 'name', '<module>')}"] = doc
    return out


# ------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------

NUMBER = re.compile(r"(?<![\w.])\d+\.\d+(?![\d.])")
VERSION = re.compile(r"\b\d+\.\d+\.\d+\b|\b(?:Python|python3?)\s+\d+\.\d+\b")


def prose(markdown: str) -> str:
    """``markdown`` without fenced code blocks, inline code and link targets (figures live in prose and tables)."""
    markdown = re.sub(r"^```.*?^```", "", markdown, flags=re.S | re.M)
    markdown = re.sub(r"`[^`\n]*`", "", markdown)
    markdown = re.sub(r"\]\([^)]*\)", "]", markdown)
    return VERSION.sub("", markdown)


def decimals(text: str) -> set[str]:
    """The decimal figures of ``text`` as written ("0.0181", "89.6"), versions left out."""
    return set(NUMBER.findall(prose(text)))


def sections(markdown: str) -> list[tuple[str, str]]:
    """(heading, body) of every ``##``/``###`` section of ``markdown``."""
    parts = re.split(r"^(#{2,3} .*)$", markdown, flags=re.M)
    return list(zip(parts[1::2], parts[2::2]))


def linked_docs(body: str) -> list[Path]:
    """The repository documents (``docs/*.md``, ``samples/README.md``) a README section links."""
    return [REPO / target for target in re.findall(r"\]\(((?:docs|samples)/[^)#]+\.md)(?:#[^)]*)?\)", body)]


def optimiser_figures(text: str, pattern: str) -> tuple[str, str]:
    """(best feasible CD, solver calls) of ``ffd optimize`` on the NACA0012 case, from ``pattern``."""
    m = re.search(pattern, re.sub(r"\s+", " ", text))
    assert m, f"no figure matching {pattern!r}"
    return m.group("cd"), m.group("calls")


# ------------------------------------------------------------------------------------------------
# tests
# ------------------------------------------------------------------------------------------------

def test_readme_is_at_most_250_lines():
    n = len(README.read_text().splitlines())
    assert n <= README_MAX_LINES, f"README.md has {n} lines: at most {README_MAX_LINES} (move detail to docs/)"


def test_readme_keeps_the_two_set_up_commands():
    text = README.read_text()
    for command in ("make demo", "make test"):
        assert re.search(rf"^{command}\b", text, flags=re.M), f"README lost its set-up command `{command}`"


@pytest.mark.parametrize("path", USER_DOCS, ids=lambda p: str(p.relative_to(REPO)))
def test_user_docs_have_no_journal_words(path):
    found = journal_words(path.read_text())
    assert not found, f"{path.relative_to(REPO)}: state the fact without its history: {found}"


def test_what_make_bench_prints_has_no_journal_words():
    found = {k: journal_words(v) for k, v in printed_benchmark_texts().items()}
    assert {k: v for k, v in found.items() if v} == {}


def test_docstrings_have_no_journal_words():
    found = {k: journal_words(v) for k, v in package_docstrings().items()}
    assert {k: v for k, v in found.items() if v} == {}


@pytest.mark.parametrize("text, expected", [
    ("Since issue 31 a shape moves", 1),
    ("the defaults before issue 13 (alpha 0.25)", 1),
    ("## Issue 27: the restructured tree", 1),
    ("a flap (issue 31) of 20 degrees", 1),
    ("with the issue-13 defaults", 1),
    ("at the end of this stop", 1),
    ("in earlier sessions one wall cell folded", 1),
    ("distorts what the parent's changes do (pyGeo issue 7)", 0),
    ("(pyGeo's issue #136)", 0),
    ("ffd's SQP stops after 8 iterations; the shock issue of the case", 0),
    ("the flow stopped; a session of SU2", 0),
])
def test_journal_words_are_recognised(text, expected):
    assert len(journal_words(text)) == expected, journal_words(text)


def test_readme_figures_are_in_the_documents_each_section_links():
    """Every decimal figure of a README section that links documents is written in one of them."""
    missing = {}
    for heading, body in sections(README.read_text()):
        docs = linked_docs(body)
        if not docs:
            continue
        theirs = set().union(*(decimals(d.read_text()) for d in docs))
        lost = sorted(decimals(body) - theirs)
        if lost:
            missing[heading] = (lost, [str(d.relative_to(REPO)) for d in docs])
    assert missing == {}, f"README figures not in the docs their section links: {missing}"


OPTIMISER_PATTERNS = {
    "README.md": r"feasible CD of (?P<cd>0\.\d+) from 0\.\d+ in (?P<calls>\d+) solver calls",
    "docs/optimize.md": r"\*\*Result with the shipped file[^*]*?CD (?P<cd>0\.\d+)[^*]*?(?P<calls>\d+) solver calls",
    "docs/BENCHMARKS.md": r"\| `ffd optimize`[^|]*\| best feasible CD (?P<cd>0\.\d+) in (?P<calls>\d+) solver calls",
}


def test_the_optimisers_cd_is_the_same_in_readme_optimize_md_and_benchmarks():
    """README's best feasible CD of ``ffd optimize`` on the NACA0012 case is optimize.md's result and
    BENCHMARKS.md's figure, with the same number of solver calls."""
    figures = {name: optimiser_figures((REPO / name).read_text(), pattern)
               for name, pattern in OPTIMISER_PATTERNS.items()}
    assert len(set(figures.values())) == 1, f"ffd optimize's best feasible CD and calls differ: {figures}"


def test_the_figure_checks_catch_a_stale_figure():
    """The checks above fail on README's old 0.002418 against optimize.md's 0.002325."""
    readme = README.read_text()
    cd, _ = optimiser_figures(readme, OPTIMISER_PATTERNS["README.md"])
    stale = readme.replace(f"feasible CD of {cd}", "feasible CD of 0.002418")
    assert optimiser_figures(stale, OPTIMISER_PATTERNS["README.md"])[0] == "0.002418"
    doc_cd, _ = optimiser_figures((DOCS / "optimize.md").read_text(), OPTIMISER_PATTERNS["docs/optimize.md"])
    assert doc_cd != "0.002418"
    speed = dict(sections(readme))["## Speed"]
    figure = sorted(decimals(speed))[0]
    changed = speed.replace(figure, figure + "7")
    assert decimals(changed) - decimals((DOCS / "BENCHMARKS.md").read_text())
