"""Graphviz export (``sotpy.graph.dot``): SoT's layout (one box per entity, one labelled
edge per plug, left to right), clusters for ordered groups, and rendering with ``dot``."""

from __future__ import annotations

import re
import shutil

import pytest

from sotpy.errors import GraphvizError
from sotpy.graph import DOUBLE, Entity, Input, Output, graphDot, plug, pool, writeGraph


class DotAdd(Entity):
    """out = a + b."""

    a = Input(DOUBLE)
    b = Input(DOUBLE, default=0.0)

    @Output(DOUBLE, deps=("a", "b"))
    def out(self, a, b):
        return a + b


class DotSource(Entity):
    @Output(DOUBLE, withTime=True, timeDependent=True)
    def clock(self, t):
        return float(t)


class DotSolver(Entity):
    """Draws its stack of tasks as a cluster, highest priority first."""

    def __init__(self, name: str) -> None:
        self.stack: list[Entity] = []

    def graphClusters(self):
        return [("stack of tasks", list(self.stack))]


NODE = re.compile(r'^\s*"([^"]+)" \[label="([^"]*)"\];', re.M)  # label may span lines
EDGE = re.compile(r'^\s*"([^"]+)" -> "([^"]+)" \[(.*)\];$')


def _edges(text: str) -> list[tuple[str, str, str]]:
    return [m.groups() for line in text.splitlines() if (m := EDGE.match(line))]


def _graph():
    src = DotSource("src")
    x, y = DotAdd("x"), DotAdd("y")
    plug(src.clock, x.a)
    plug(src.clock, y.a)
    plug(x.out, y.b)
    DotAdd("lonely")
    return src, x, y


def test_one_box_per_entity_and_one_labelled_edge_per_plug():
    _graph()
    text = graphDot("demo")
    assert 'digraph "demo" {' in text
    assert "rankdir=LR" in text
    boxes = NODE.findall(text)
    assert sorted(n for n, _ in boxes) == ["lonely", "src", "x", "y"]
    labels = dict(boxes)
    for name, cls in (("src", "DotSource"), ("x", "DotAdd"), ("y", "DotAdd"), ("lonely", "DotAdd")):
        assert name in labels[name] and cls in labels[name]
    edges = _edges(text)
    assert len(edges) == 3
    labelled = set()
    for tail, head, attrs in edges:
        h = re.search(r'headlabel="([^"]+)"', attrs).group(1)
        t = re.search(r'taillabel="([^"]+)"', attrs).group(1)
        labelled.add((tail, t, head, h))
    assert labelled == {
        ("src", "clock", "x", "a"),
        ("src", "clock", "y", "a"),
        ("x", "out", "y", "b"),
    }


def test_inputs_holding_constants_draw_no_edge():
    _, x, _ = _graph()
    x.a.value = 3.0  # unplugs
    edges = _edges(graphDot())
    assert ("src", "x") not in {(t, h) for t, h, _ in edges}
    assert len(edges) == 2


def test_a_cluster_chains_its_members_in_order_with_red_edges():
    tasks = [DotAdd(n) for n in ("t_high", "t_mid", "t_low")]
    sot = DotSolver("sot")
    sot.stack = [tasks[1], tasks[0], tasks[2]]  # priority order, not creation order
    text = graphDot()
    assert text.count("subgraph cluster_") == 1
    cluster = text[text.index("subgraph cluster_") :]
    cluster = cluster[: cluster.index("}")]
    assert "stack of tasks" in cluster
    for t in tasks:
        assert f'"{t.name}"' in cluster
    red = [(t, h) for t, h, attrs in _edges(text) if "color=red" in attrs]
    assert red == [("t_mid", "t_high"), ("t_high", "t_low")]


def test_no_cluster_without_graphClusters():
    _graph()
    assert "subgraph cluster_" not in graphDot()


def test_writeGraph_writes_dot_text(tmp_path):
    _graph()
    path = tmp_path / "graph.dot"
    assert writeGraph(str(path)) == str(path)
    text = path.read_text()
    assert 'digraph "graph"' in text
    assert len(_edges(text)) == 3
    assert pool.writeGraph(str(tmp_path / "again.dot")).endswith("again.dot")


@pytest.mark.needs("dot")
def test_writeGraph_renders_svg_with_graphviz(tmp_path):
    _graph()
    sot = DotSolver("sot")
    sot.stack = [DotAdd("t1"), DotAdd("t2")]
    path = tmp_path / "graph.svg"
    assert writeGraph(str(path)) == str(path)
    svg = path.read_text()
    assert "<svg" in svg
    for name in ("src", "x", "y", "lonely", "t1", "t2", "sot"):
        assert f"<title>{name}</title>" in svg
    assert (tmp_path / "graph.dot").exists()


def test_writeGraph_without_graphviz_raises_after_writing_dot(tmp_path, monkeypatch):
    _graph()
    monkeypatch.setattr(shutil, "which", lambda *args, **kwargs: None)
    path = tmp_path / "graph.svg"
    with pytest.raises(GraphvizError, match="dot"):
        writeGraph(str(path))
    assert not path.exists()
    dot = tmp_path / "graph.dot"
    assert dot.exists()
    assert len(_edges(dot.read_text())) == 3
