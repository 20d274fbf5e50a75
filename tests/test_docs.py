"""The documentation stays true: links resolve, marked examples run, the site builds.

- every relative link of README.md and docs/*.md names an existing file;
- the Python blocks of the tutorials marked runnable run without error, in order, in a
  fresh pool (a block is runnable when the line before its opening fence is the HTML
  comment ``<!-- test -->``, invisible in the rendered page; ``<!-- test: needs dot -->``
  marks a block that needs a system program: it runs only where that program is
  installed, in a second test that is skipped elsewhere, so that the README's test
  command passes on a machine with only Python); the printed output shown after a
  block is the author's record, not compared here (it holds floats and addresses);
- the Sphinx site (docs/conf.py) builds with ``-W -n``: a broken reference in a
  docstring or a page fails; skipped when Sphinx is not installed (``pip install
  -e '.[docs]'``; CI installs it before running the tests);
- the README's test command is one line, the one ``.ci/run`` runs.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
MARKDOWN = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
RUNNABLE_PAGES = ["tutorial-debugging.md", "porting.md"]

_FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.S | re.M)
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_RUNNABLE = re.compile(
    r"^<!-- test(?:: needs (?P<needs>[\w, -]+))? -->[ \t]*\n"
    r"```python[ \t]*\n(?P<code>.*?)^```[ \t]*$",
    re.S | re.M,
)


def relative_links(page: Path) -> list[str]:
    """The link targets of a Markdown page that are files of the repository (no URL,
    no in-page anchor), outside fenced code blocks, without their ``#anchor``."""
    text = _FENCE.sub("", page.read_text())
    out = []
    for target in _LINK.findall(text):
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue  # https:, mailto:, an anchor in the page
        out.append(target.split("#", 1)[0])
    return out


def runnable_blocks(page: Path) -> list[tuple[str, tuple[str, ...]]]:
    """The Python blocks of ``page`` marked ``<!-- test -->`` (or ``<!-- test: needs
    PROGRAM, ... -->``), in page order: ``(code, programs needed)``."""
    return [
        (m["code"], tuple(p.strip() for p in (m["needs"] or "").split(",") if p.strip()))
        for m in _RUNNABLE.finditer(page.read_text())
    ]


def _programs(name: str) -> tuple[str, ...]:
    return tuple(sorted({p for _, needs in runnable_blocks(DOCS / name) for p in needs}))


def test_block_extraction_reads_the_needs_marker(tmp_path):
    page = tmp_path / "p.md"
    page.write_text(
        "<!-- test -->\n```python\na = 1\n```\n\n```python\nskipped = 1\n```\n"
        "<!-- test: needs dot, chromium -->\n```python\nb = 2\n```\n"
    )
    assert runnable_blocks(page) == [("a = 1\n", ()), ("b = 2\n", ("dot", "chromium"))]


def test_link_extraction_finds_relative_links_and_skips_urls_and_code(tmp_path):
    page = tmp_path / "p.md"
    page.write_text(
        "[a](graph.md) [b](https://x.org/y.md) ![c](img/z.svg) [d](#here)\n"
        "[e](tasks.md#the-contract)\n```python\n[f](inside-code.md)\n```\n"
    )
    assert relative_links(page) == ["graph.md", "img/z.svg", "tasks.md"]


@pytest.mark.parametrize("page", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_to_existing_files(page):
    links = relative_links(page)
    missing = [t for t in links if not (page.parent / t).exists()]
    assert not missing, f"{page.relative_to(ROOT)} links to missing files: {missing}"


def test_every_doc_page_is_linked_from_the_site_index():
    index = (DOCS / "index.md").read_text()
    pages = [p.stem for p in DOCS.glob("*.md") if p.name != "index.md"]
    unlisted = [p for p in pages if not re.search(rf"^{re.escape(p)}$", index, re.M)]
    assert not unlisted, f"docs pages missing from the toctree of docs/index.md: {unlisted}"


def _run_blocks(name: str, tmp_path: Path, monkeypatch, capsys, everything: bool) -> str:
    """Run the page's runnable blocks (those needing no program, or all) and check the
    story the page tells; returns what they printed."""
    blocks = runnable_blocks(DOCS / name)
    assert len(blocks) >= 1, f"docs/{name} has no block marked <!-- test -->"
    monkeypatch.chdir(tmp_path)  # files the examples write (writeGraph) land here
    namespace: dict = {"__name__": "__main__"}
    for i, (block, needs) in enumerate(blocks):
        if needs and not everything:
            continue
        code = compile(block, f"docs/{name}, runnable block {i + 1}", "exec")
        exec(code, namespace)  # the pool was cleared by conftest
    printed = capsys.readouterr().out
    if name == "tutorial-debugging.md":
        # the story the page tells: two unset inputs found, then none, the picture drawn
        assert "FeaturePose(feature_ee)::input(matrix)::Jq" in printed
        assert "SOT(sot)::input(double)::dt" in printed
        assert "[]" in printed
        assert (tmp_path / "ur5-reach.dot").exists() == everything
        if everything:
            assert "<svg" in (tmp_path / "ur5-reach.svg").read_text()
    if name == "porting.md":
        assert "['tasklf', 'taskrh']" in printed
        assert (tmp_path / "graph.dot").exists()
    return printed


@pytest.mark.parametrize("name", RUNNABLE_PAGES)
def test_runnable_blocks_run(name, tmp_path, monkeypatch, capsys):
    """The blocks that need only Python (those marked ``needs`` are left out)."""
    _run_blocks(name, tmp_path, monkeypatch, capsys, everything=False)


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(name, marks=pytest.mark.needs(*_programs(name)))
        for name in RUNNABLE_PAGES
        if _programs(name)
    ],
)
def test_runnable_blocks_with_programs_run(name, tmp_path, monkeypatch, capsys):
    """Every runnable block, those that need a program included (skipped without it)."""
    _run_blocks(name, tmp_path, monkeypatch, capsys, everything=True)


def test_readme_test_command_is_the_one_ci_runs():
    """One line after "CI runs exactly this line", which .ci/run reads from the README
    (so that the two cannot drift apart) and runs twice: without dot and Chromium, then
    with them."""
    readme = (ROOT / "README.md").read_text()
    after = readme.split("CI runs exactly this line", 1)[1]
    block = re.search(r"```sh\n(.*?)```", after, re.S)
    assert block is not None
    lines = block.group(1).strip().splitlines()
    assert len(lines) == 1 and lines[0].endswith(".venv/bin/python -m pytest")
    assert "pip install -e '.[test]'" in lines[0]
    ci = (ROOT / ".ci" / "run").read_text()
    assert "CI runs exactly this line" in ci  # the marker it reads the line after


def test_debugging_picture_is_committed():
    picture = DOCS / "img" / "debugging-ur5.svg"
    assert picture.exists()
    assert "<svg" in picture.read_text()[:2000]


@pytest.mark.needs("sphinx")
def test_sphinx_site_builds_without_warnings(tmp_path):
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-q", "-b", "html"]
    cmd += ["-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "html")]
    result = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f"sphinx failed:\n{result.stderr[-5000:]}"
    html = tmp_path / "html"
    for page in ["index.html", "tutorial-debugging.html", "porting.html", "api/graph.html"]:
        assert (html / page).exists(), page
    # the API reference is generated from the docstrings
    assert "displaySignals" in (html / "api" / "graph.html").read_text()
    assert (html / "_images" / "debugging-ur5.svg").exists()  # the rendered picture
