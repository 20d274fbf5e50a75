"""The dashboard in a real browser (headless Chromium, skipped without it): the page
finds the graph's entities, a plot added by clicks shows data that advances, a gain
edited in the page changes the signal, a bad value is refused with sotpy's message."""

from __future__ import annotations

import struct
import time

import pytest

from sotpy.dashboard import Dashboard
from sotpy.loop import ControlLoop
from test_dashboard import DT, _pinnedLoop, ur5_reach

pytestmark = pytest.mark.needs("chromium")


def _click(page, selector: str) -> None:
    found = page.evaluate(
        f"(() => {{ const e = document.querySelector({selector!r}); if (!e) return false; "
        "e.click(); return true; })()"
    )
    assert found, f"no element {selector}"


def _type(page, selector: str, text: str) -> None:
    page.evaluate(f"document.querySelector({selector!r}).value = {text!r}")


def test_page_graph_plot_edit_refusal(tmp_path):
    from sotpy.dashboard.browser import HeadlessPage

    robot, _feature, task, _sot = ur5_reach()
    loop = ControlLoop("loop", robot.device, DT)
    with Dashboard(loop, robot=robot) as ui, HeadlessPage(ui.url(), 1500, 950) as page:
        loop.start()
        # the graph's entities, in the list and in the drawn graph
        page.waitFor("document.querySelectorAll('#graph .node').length >= 6")
        listed = page.evaluate(
            "[...document.querySelectorAll('#entities .entity')].map(e => e.dataset.entity)"
        )
        drawn = page.evaluate(
            "[...document.querySelectorAll('#graph .node')].map(e => e.dataset.entity)"
        )
        for name in ("sot", "task_ee", "feature_ee", "ur5_dynamic", "ur5_device", "loop"):
            assert name in listed and name in drawn
        edges = page.evaluate("document.querySelectorAll('#graph .edge').length")
        assert edges >= 4
        # a plot, by clicks: open the task, 'plot' its error, pick every component
        _click(page, '.entity[data-entity="task_ee"] .head')
        _click(page, '.sig[data-path="task_ee.error"] .acts button')
        page.waitFor("document.querySelector('.picker') !== null")
        _click(page, ".picker button:nth-of-type(2)")  # "all"
        page.waitFor("sotpyDashboard.x.length > 5", 20)
        first = page.evaluate("sotpyDashboard.x[sotpyDashboard.x.length - 1]")
        time.sleep(1.0)
        last = page.evaluate("sotpyDashboard.x[sotpyDashboard.x.length - 1]")
        assert last > first + 0.3  # simulated seconds advance with the loop (100 Hz)
        # the plot draws at the display's frames what arrived: once a display frame at
        # most, its last drawn time that of the rows (a frame or two behind at most)
        xs, drawn, draws, frames = page.evaluate(
            "(() => { const S = sotpyDashboard, u = S.plots.find((q) => q.u).u;"
            " return [S.x[S.x.length - 1], u.data[0][u.data[0].length - 1], S.draws,"
            " S.frames]; })()"
        )
        assert 0 <= xs - drawn <= 0.2, (xs, drawn)
        assert 0 < draws <= frames, (draws, frames)
        lines = page.evaluate("document.querySelectorAll('.plot .u-series').length")
        assert lines == 1 + 3  # time + the three components selected by "111000"
        y = page.evaluate(
            "(() => { const c = sotpyDashboard.cols.values().next().value[0];"
            " return c[c.length - 1]; })()"
        )
        # the plotted error is the task's, at its tick
        assert abs(y - float(task.error.value[0])) < 0.05
        # the fresh marks: the plotted error is computed at every tick (by the recorder)
        page.waitFor(
            "document.querySelector('.sig[data-path=\"task_ee.error\"]').classList"
            ".contains('fresh')"
        )
        # edit the gain from the page; the page shows the new value, the graph has it
        gain = '.sig[data-path="task_ee.controlGain"]'
        _type(page, f"{gain} .edit input", "5")
        _click(page, f"{gain} .edit button")
        page.waitFor(f"document.querySelector('{gain} .val').textContent.trim() == '5.0'")
        assert task.controlGain.value == 5.0
        # a bad value: refused, with the signal's name and what it expects
        _type(page, f"{gain} .edit input", "[1, 2]")
        _click(page, f"{gain} .edit button")
        text = page.waitFor(
            "(() => { const e = document.querySelector('#log .err');"
            " return e && e.textContent; })()"
        )
        assert "REFUSED" in text and "Task(task_ee)::input(double)::controlGain" in text
        assert "expected a real number" in text
        assert task.controlGain.value == 5.0
        # the stack panel shows the SOT's levels with their residuals
        page.waitFor(
            'document.querySelector(\'table[data-sot="sot"] tr[data-task="task_ee"]\') !== null'
        )
        shot = page.screenshot(tmp_path / "dashboard.png")
        assert loop.running and loop.fault is None
        loop.stop()
    with open(shot, "rb") as f:
        png = f.read()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert struct.unpack(">II", png[16:24]) == (1500, 950)


def _descendants(pid: int) -> set[int]:
    """``pid`` and every process below it (read from /proc)."""
    import os

    parents: dict[int, int] = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    parents[int(d)] = int(f.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
    out, todo = {pid}, [pid]
    while todo:
        p = todo.pop()
        for child, parent in parents.items():
            if parent == p and child not in out:
                out.add(child)
                todo.append(child)
    return out


def test_a_browser_given_cpus_runs_every_process_there():
    import os

    from sotpy.dashboard.browser import HeadlessPage

    cpus, loop = _pinnedLoop()
    with Dashboard(loop) as ui, HeadlessPage(ui.url(), 800, 600, cpus=loop.otherCpus()) as page:
        page.waitFor("document.querySelectorAll('#graph .node').length >= 6")
        procs = _descendants(page._proc.pid)
        assert len(procs) >= 3  # the browser, its renderer, its helpers
        for pid in procs:
            try:
                assert os.sched_getaffinity(pid) == set(cpus[:-1]), pid
            except ProcessLookupError:
                continue  # a helper that ended meanwhile
