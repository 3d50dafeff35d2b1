"""The user documentation (README.md, CHANGELOG.md, docs/*.md and the folder READMEs) agrees with the
code and the tree: the generated pages are up to date, README stays short and links every page,
every link, backticked repository path and backticked ``hikbench.*`` name names something that
exists, and no page reads as a work log."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted(DOCS.glob("*.md")),
         ROOT / "problems" / "robots" / "README.md"]
README_MAX_LINES = 250

#: the first component of a backticked span that is read as a repository path
TOP = {p.name for p in ROOT.iterdir() if not p.name.startswith(".") or p.name == ".ci"} - {".venv"}
#: folders that commands write under results/ (git-ignored: .gitignore's /results/*/); the committed
#: ones (sample, peers) must exist
RUN_OUTPUTS = {"quick", "paper", "ci", "regress", "scenarios", "mine", "external", "units"}
_PATH = re.compile(r"^[A-Za-z0-9_.\-/]+$")
_PLACEHOLDER = re.compile(r"(^|/)[A-Z][A-Z0-9_]*(/|$|\.)")  # NAME, OUT, RUN, DIR as a component


def _rel(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


def _prose(text: str) -> str:
    """The text outside code blocks (fenced, or indented by 4 spaces)."""
    out, fenced = [], False
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            fenced = not fenced
            continue
        if fenced or line.startswith(("    ", "\t")):
            continue
        out.append(line)
    return "\n".join(out)


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    s = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return s.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    return {_slug(m.group(1)) for m in re.finditer(r"^#+ (.+)$", _prose(page.read_text()), re.M)}


def _links(page: Path) -> list[tuple[str, str]]:
    """(kind, target) of every relative markdown link, backticked repository path and backticked
    ``hikbench.*`` name of a page."""
    prose = _prose(page.read_text())
    refs = []
    for m in re.finditer(r"\[[^\]]*\]\(([^)\s]+)\)", prose):
        target = m.group(1)
        if not re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
            refs.append(("link", target))
    for m in re.finditer(r"`((?:[^`\n]|\n(?!\n))+)`", prose):  # (a span may wrap, within a paragraph)
        for token in m.group(1).split():  # (a command line names paths too)
            span = token.split(":")[0].rstrip(".,;)")  # (file.py:Class, module:function)
            if not _PATH.match(span) or "/" not in span and span not in TOP:
                continue
            if span.split("/")[0] not in TOP or _PLACEHOLDER.search(span):
                continue
            parts = span.split("/")
            if parts[0] == "results" and len(parts) > 1 and parts[1] in RUN_OUTPUTS:
                continue
            refs.append(("path", span))
        refs += [("python", d.group(0)) for d in re.finditer(r"\bhikbench(\.\w+)+", m.group(1))]
    return list(dict.fromkeys(refs))


CASES = [(page, kind, target) for page in PAGES if page.exists() for kind, target in _links(page)]


def test_docs_exist():
    assert (ROOT / "CHANGELOG.md").exists()
    assert DOCS.is_dir() and len(list(DOCS.glob("*.md"))) >= 10


@pytest.mark.parametrize(("page", "kind", "target"), CASES,
                         ids=[f"{_rel(p)}:{k}:{t}" for p, k, t in CASES])
def test_every_link_and_repository_path_exists(page, kind, target):
    if kind == "link":
        file_part, _, anchor = target.partition("#")
        path = (page.parent / file_part).resolve() if file_part else page
        assert path.exists(), f"{_rel(page)} links {target}: no such file"
        if anchor and path.suffix == ".md":
            assert anchor in _anchors(path), f"{_rel(page)} links {target}: no such heading"
    elif kind == "path":
        assert (ROOT / target).exists(), f"{_rel(page)} names `{target}`: no such file or folder"
    else:
        assert _python_object_exists(target), f"{_rel(page)} names `{target}`: no such module or attribute"


def _python_object_exists(dotted: str) -> bool:
    """``hikbench.a.b[.attr...]`` names a module of the package, or an attribute of one."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        name = ".".join(parts[:i])
        try:
            obj = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name is not None and not name.startswith(err.name) and not err.name.startswith(name):
                raise  # a dependency of the module is missing: not the doc's fault
            continue
        for attr in parts[i:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_cli_reference_is_generated_from_the_parser():
    from hikbench.bench import clidoc

    assert (DOCS / "cli.md").read_text() == clidoc.markdown(), (
        "docs/cli.md is out of date: python -m hikbench.bench.clidoc > docs/cli.md")


def test_cli_reference_documents_every_command():
    from hikbench.bench.cli import COMMANDS

    text = (DOCS / "cli.md").read_text()
    for name in COMMANDS:
        assert f"## hikbench {name}\n" in text


def test_columns_page_holds_the_generated_table():
    from hikbench.bench.harness.columns import markdown

    assert markdown() in (DOCS / "columns.md").read_text(), (
        "docs/columns.md's table is out of date: paste `hikbench columns --markdown`")


def test_readme_is_short():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"


@pytest.mark.parametrize("page", sorted(DOCS.glob("*.md")), ids=lambda p: p.name)
def test_readme_links_every_docs_page(page):
    assert f"(docs/{page.name}" in (ROOT / "README.md").read_text()


_LOG = re.compile(r"\b\w+(th|st|nd|rd) session\b|\bsession \d|\baudit \d|\bfinding \d|\b20\d\d-\d\d-\d\d\b"
                  r"|\b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b", re.I)


@pytest.mark.parametrize("page", [p for p in PAGES if p.name != "CHANGELOG.md"], ids=_rel)
def test_no_page_reads_as_a_work_log(page):
    """No session counts, audit or finding numbers, dates of work or commit hashes."""
    hits = [m.group(0) for m in _LOG.finditer(page.read_text())]
    assert not hits, f"{_rel(page)}: {hits}"


def test_the_quick_suites_duration_is_one_number():
    """README, docs/suites.md and the suite's own description (``hikbench list suites``) say the
    same time for a run of the quick suite (a new --out: its certificates computed, kernels cached)."""
    import tomllib

    description = tomllib.loads((ROOT / "bench" / "suites" / "quick.toml").read_text())["description"]
    quick_row = next(line for line in (DOCS / "suites.md").read_text().splitlines() if line.startswith("| `quick` |"))
    said = {"README.md": re.search(r"the quick suite then takes about (\d+) s\b",
                                   " ".join((ROOT / "README.md").read_text().split())),
            "docs/suites.md": re.search(r"about (\d+) s\b", quick_row),
            "bench/suites/quick.toml": re.search(r"about (\d+) s\b", description)}
    missing = [where for where, m in said.items() if m is None]
    assert not missing, f"no 'about N s' for the quick suite in {missing}"
    seconds = {where: int(m.group(1)) for where, m in said.items()}
    assert len(set(seconds.values())) == 1, seconds
