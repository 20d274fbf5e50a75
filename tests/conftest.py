"""Shared fixtures and the ``needs`` marker.

- Every test starts and ends with an empty pool at tick 0.
- The compiled kernels are compiled before use (``SOTPY_JIT=wait``, unless the
  environment sets it), not in the background as a first run does: a test must know
  which twin it runs. ``tests/test_jit.py`` runs the background compile itself.
- ``@pytest.mark.needs("dot")`` (or ``"chromium"``, ``"sphinx"``): the test needs a
  program that ``pip install -e '.[test]'`` does not bring (Graphviz's ``dot``, a
  headless Chromium, the documentation tools of the ``docs`` extra); it is skipped,
  with the reason and the install command, where that program is missing. Set
  ``SOTPY_TEST_REQUIRE=dot,chromium,sphinx`` (what ``.ci/run`` does once it has
  installed them) to make such a test fail instead of skipping, so that a run that
  promised them cannot pass without running those tests.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

os.environ.setdefault("SOTPY_JIT", "wait")  # before sotpy is imported

from sotpy.graph.pool import pool


def _chromium() -> str | None:
    from sotpy.viewer import findChromium

    return findChromium()


def _sphinx() -> str | None:
    found = all(importlib.util.find_spec(m) is not None for m in ("sphinx", "myst_parser"))
    return "sphinx" if found else None


#: What a ``needs`` marker may name: a finder (the program's path, or None when it is
#: missing) and how to install it.
PROGRAMS: dict[str, tuple[Callable[[], str | None], str]] = {
    "dot": (lambda: shutil.which("dot"), "Graphviz's 'dot' (apt-get install graphviz)"),
    "chromium": (_chromium, "Chromium (bash tools/install-browser.sh)"),
    "sphinx": (_sphinx, "Sphinx and myst-parser (pip install -e '.[docs]')"),
}


def missing_programs(names: tuple[str, ...]) -> list[str]:
    """The programs of ``names`` that are not installed here, each as its install hint."""
    out = []
    for name in names:
        if name not in PROGRAMS:
            raise pytest.UsageError(f"needs({name!r}): unknown program; known: {list(PROGRAMS)}")
        find, hint = PROGRAMS[name]
        if find() is None:
            out.append(hint)
    return out


def required_programs() -> set[str]:
    """The programs ``SOTPY_TEST_REQUIRE`` (comma-separated) says must be there."""
    text = os.environ.get("SOTPY_TEST_REQUIRE", "")
    return {p.strip() for p in text.split(",") if p.strip()}


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "needs(*programs): skip unless the programs are installed (dot, chromium, sphinx); "
        "fail instead when SOTPY_TEST_REQUIRE names them",
    )


def pytest_runtest_setup(item: pytest.Item) -> None:
    names = tuple(n for mark in item.iter_markers("needs") for n in mark.args)
    if not names:
        return
    missing = missing_programs(names)
    if not missing:
        return
    required = required_programs() & set(names)
    text = f"needs {', '.join(missing)}"
    if any(PROGRAMS[n][1] in missing for n in required):
        pytest.fail(f"{text}, which SOTPY_TEST_REQUIRE={sorted(required)} requires", False)
    pytest.skip(text)


def check_figure(fig, title: str) -> dict[str, dict]:
    """The checks every demo figure passes: a title containing ``title``; on every axis
    a title, a y label with a unit in brackets that is not both metres and radians, and
    a legend naming every labelled line; an x label on the figure. Returns
    ``{axis title: {"ylabel": ..., "legend": [texts], "lines": {label: line}}}``."""
    assert fig._suptitle is not None and title in fig._suptitle.get_text()
    out = {}
    for ax in fig.axes:
        name = ax.get_title()
        assert name, "an axis without a title"
        ylabel = ax.get_ylabel()
        assert "[" in ylabel and "]" in ylabel, f"{name}: no unit in {ylabel!r}"
        assert not ("m]" in ylabel and "rad" in ylabel), f"{name}: mixes m and rad"
        legend = ax.get_legend()
        assert legend is not None, f"{name}: no legend"
        texts = [t.get_text() for t in legend.get_texts()]
        labelled = [ln for ln in ax.get_lines() if not ln.get_label().startswith("_")]
        assert labelled and [ln.get_label() for ln in labelled] == texts
        out[name] = {
            "ylabel": ylabel,
            "legend": texts,
            "lines": {ln.get_label(): ln for ln in labelled},
        }
    bottom = [ax for ax in fig.axes if ax.get_xlabel()]
    assert bottom, "no x label"
    return out


@pytest.fixture
def figure_check():
    """:func:`check_figure`, for the tests of the demos' figures."""
    return check_figure


@pytest.fixture(autouse=True)
def _clear_pool():
    """Clear the pool (entities, clock) before and after each test."""
    pool.clear()
    yield
    pool.clear()


@pytest.fixture(scope="module")
def bench_sot():
    """``benchmarks/bench_sot.py`` as a module (registered in ``sys.modules`` while the
    test module runs: its dataclasses look their module up there)."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_sot.py"
    spec = importlib.util.spec_from_file_location("bench_sot", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)
