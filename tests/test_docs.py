"""The documentation stays true: links resolve, marked examples run, the site builds.

- every relative link of README.md and docs/*.md names an existing file;
- the Python blocks of the tutorials marked runnable run without error, in order, in a
  fresh pool (a block is runnable when the line before its opening fence is the HTML
  comment ``<!-- test -->``, invisible in the rendered page); the printed output shown
  after a block is the author's record, not compared here (it holds floats and
  addresses);
- the Sphinx site (docs/conf.py) builds with ``-W -n``: a broken reference in a
  docstring or a page fails; skipped when Sphinx is not installed (``pip install
  -e '.[docs]'``).
"""

from __future__ import annotations

import importlib.util
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
_RUNNABLE = re.compile(r"^<!-- test -->[ \t]*\n```python[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)


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


def runnable_blocks(page: Path) -> list[str]:
    """The Python blocks of ``page`` marked ``<!-- test -->``, in page order."""
    return _RUNNABLE.findall(page.read_text())


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


@pytest.mark.parametrize("name", RUNNABLE_PAGES)
def test_runnable_blocks_run(name, tmp_path, monkeypatch, capsys):
    blocks = runnable_blocks(DOCS / name)
    assert len(blocks) >= 1, f"docs/{name} has no block marked <!-- test -->"
    monkeypatch.chdir(tmp_path)  # files the examples write (writeGraph) land here
    namespace: dict = {"__name__": "__main__"}
    for i, block in enumerate(blocks):
        code = compile(block, f"docs/{name}, runnable block {i + 1}", "exec")
        exec(code, namespace)  # the pool was cleared by conftest
    printed = capsys.readouterr().out
    if name == "tutorial-debugging.md":
        # the story the page tells: two unset inputs found, then none, the picture drawn
        assert "FeaturePose(feature_ee)::input(matrix)::Jq" in printed
        assert "SOT(sot)::input(double)::dt" in printed
        assert "[]" in printed
        assert (tmp_path / "ur5-reach.svg").exists() or not _has_dot()
    if name == "porting.md":
        assert "['tasklf', 'taskrh']" in printed
        assert (tmp_path / "graph.dot").exists()


def _has_dot() -> bool:
    import shutil

    return shutil.which("dot") is not None


def test_debugging_picture_is_committed():
    picture = DOCS / "img" / "debugging-ur5.svg"
    assert picture.exists()
    assert "<svg" in picture.read_text()[:2000]


@pytest.mark.skipif(
    importlib.util.find_spec("sphinx") is None or importlib.util.find_spec("myst_parser") is None,
    reason="Sphinx and myst-parser are not installed (pip install -e '.[docs]')",
)
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
