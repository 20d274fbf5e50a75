"""The Tracer entity (``sotpy.graph.tracer``): rows recorded at each trigger, npz and CSV
dumps read back with numpy, time in seconds, downsampling, and the three overflow
policies (none of which drops data silently)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from sotpy.errors import CommandError, SignalTypeError, SotpyError, SotpyWarning, TracerOverflow
from sotpy.graph import (
    DOUBLE,
    MATRIX,
    STRING,
    VECTOR,
    Entity,
    Input,
    Output,
    PeriodicCall,
    Tracer,
    pool,
)


class TrcClock(Entity):
    """Time-dependent test signals."""

    def __init__(self, name: str) -> None:
        self.calls = 0

    @Output(VECTOR, withTime=True, timeDependent=True)
    def vec(self, t):
        self.calls += 1
        return np.array([t, 2.0 * t, -t / 3.0])

    @Output(DOUBLE, withTime=True, timeDependent=True)
    def half(self, t):
        return 0.5 * t

    @Output(MATRIX, withTime=True, timeDependent=True)
    def mat(self, t):
        return np.array([[t, 1.0], [2.0, -t]])


class TrcInputs(Entity):
    x = Input(DOUBLE, default=0.0)
    label = Input(STRING, default="hi")

    @Output(STRING, deps=("label",))
    def text(self, label):
        return label


def vec_ref(t):
    return [t, 2.0 * t, -t / 3.0]


def _tracer(name="tr", **kw) -> tuple[Tracer, TrcClock]:
    c = TrcClock("clock")
    tr = Tracer(name, **kw)
    tr.add(c.vec)
    tr.add("clock.half", "h")
    return tr, c


def test_records_the_traced_signals_at_each_trigger():
    tr, c = _tracer()
    tr.start()
    for t in range(5):
        assert tr.trigger.recompute(t) == t + 1
    d = tr.data()
    np.testing.assert_array_equal(d["time"], np.arange(5))
    np.testing.assert_array_equal(d["clock.vec"], [vec_ref(t) for t in range(5)])
    np.testing.assert_array_equal(d["h"], [[0.5 * t] for t in range(5)])
    assert d["clock.vec"].shape == (5, 3)
    assert c.calls == 5  # one computation per tick


def test_trigger_computes_outdated_signals_once_per_tick():
    tr, c = _tracer()
    tr.start()
    for t in range(4):
        c.vec(t)  # read first: the tracer reuses the value
        tr.trigger(t)
        tr.trigger(t)  # a second read in the same tick records nothing
    assert c.calls == 4
    np.testing.assert_array_equal(tr.data()["time"], np.arange(4))


def test_nothing_is_recorded_before_start_or_after_stop():
    tr, _ = _tracer()
    tr.trigger(0)
    tr.start()
    tr.trigger(1)
    tr.trigger(2)
    tr.stop()
    tr.trigger(3)
    np.testing.assert_array_equal(tr.data()["time"], [1, 2])
    assert "stopped" in tr.status()


def test_dump_npz_reads_back(tmp_path):
    tr, _ = _tracer()
    tr.add("clock.mat")
    tr.start()
    for t in range(6):
        tr.trigger(t)
    path = tr.dump(str(tmp_path / "run.npz"))
    with np.load(path) as f:
        assert set(f.files) == {"time", "clock.vec", "h", "clock.mat"}
        np.testing.assert_array_equal(f["time"], np.arange(6))
        np.testing.assert_array_equal(f["clock.vec"], [vec_ref(t) for t in range(6)])
        np.testing.assert_array_equal(f["h"][:, 0], [0.5 * t for t in range(6)])
        np.testing.assert_array_equal(f["clock.mat"], [[t, 1.0, 2.0, -t] for t in range(6)])


def test_dump_csv_reads_back(tmp_path):
    tr, _ = _tracer()
    tr.start()
    for t in range(7):
        tr.trigger(t)
    path = tmp_path / "run.csv"
    tr.dump(str(path))
    header = path.read_text().splitlines()[0]
    assert header.startswith("time")
    columns = header.split(",")
    assert columns == ["time", "clock.vec[0]", "clock.vec[1]", "clock.vec[2]", "h"]
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    assert table.shape == (7, 5)
    expected = np.array([[t, *vec_ref(t), 0.5 * t] for t in range(7)])
    np.testing.assert_array_equal(table, expected)  # %.17g: exact round trip


def test_time_step_gives_seconds(tmp_path):
    tr, _ = _tracer()
    tr.setTimeStep(0.01)
    tr.start()
    for t in range(5):
        tr.trigger(t)
    d = tr.data()
    np.testing.assert_allclose(d["time"], 0.01 * np.arange(5), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(d["tick"], np.arange(5))
    path = tmp_path / "s.csv"
    tr.dump(str(path))
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    np.testing.assert_allclose(table[:, 0], 0.01 * np.arange(5), rtol=0, atol=1e-15)
    with pytest.raises(SotpyError, match=r"tr"):
        tr.setTimeStep(0.0)
    with pytest.raises(CommandError, match=r"Tracer\(tr\)\.setTimeStep"):
        tr.setTimeStep("0.1")


def test_trigger_period_records_every_k_ticks():
    tr, _ = _tracer()
    tr.trigger.setPeriod(3)
    tr.start()
    for t in range(10):
        tr.trigger(t)
    np.testing.assert_array_equal(tr.data()["time"], [0, 3, 6, 9])
    np.testing.assert_array_equal(tr.data()["clock.vec"], [vec_ref(t) for t in (0, 3, 6, 9)])


def test_trigger_period_holds_when_a_traced_constant_changes_every_tick():
    src = TrcInputs("src")
    tr = Tracer("tr")
    tr.add(src.x)
    tr.trigger.setPeriod(2)
    tr.start()
    for t in range(6):
        pool.advance(t)
        src.x.value = float(t)
        tr.trigger(t)
    np.testing.assert_array_equal(tr.data()["time"], [0, 2, 4])


def test_tracer_on_a_periodic_call():
    tr, _ = _tracer()
    after = PeriodicCall("device.after")
    after.addSignal(tr.trigger, 2)
    tr.start()
    for t in range(8):
        pool.advance(t)
        after.run(t)
    np.testing.assert_array_equal(tr.data()["time"], [0, 2, 4, 6])


def test_overflow_stop_warns_once_and_counts_dropped_rows():
    tr, _ = _tracer(bufferSize=3)
    tr.start()
    for t in range(3):
        tr.trigger(t)
    assert not tr.full
    with pytest.warns(SotpyWarning, match=r"Tracer\(tr\).*3 rows.*full") as record:
        tr.trigger(3)
        tr.trigger(4)
    assert len([w for w in record if issubclass(w.category, SotpyWarning)]) == 1
    tr.trigger(5)  # no second warning (SotpyWarning is an error outside pytest.warns)
    assert tr.full
    assert tr.dropped == 3
    assert "FULL" in tr.status()
    assert "FULL" in tr.signalsDisplay()
    d = tr.data()
    np.testing.assert_array_equal(d["time"], [0, 1, 2])
    np.testing.assert_array_equal(d["clock.vec"], [vec_ref(t) for t in range(3)])
    tr.empty()
    assert not tr.full and tr.dropped == 0
    tr.trigger(6)
    np.testing.assert_array_equal(tr.data()["time"], [6])


def test_overflow_ring_keeps_the_newest_rows_in_order():
    tr, _ = _tracer(bufferSize=3, overflow="ring")
    tr.start()
    with pytest.warns(SotpyWarning) as record:
        for t in range(8):
            tr.trigger(t)
    assert len(record) == 1
    assert tr.full
    d = tr.data()
    np.testing.assert_array_equal(d["time"], [5, 6, 7])
    np.testing.assert_array_equal(d["clock.vec"], [vec_ref(t) for t in (5, 6, 7)])
    np.testing.assert_array_equal(d["h"][:, 0], [2.5, 3.0, 3.5])


def test_overflow_ring_counts_every_overwritten_row():
    tr, _ = _tracer(bufferSize=3, overflow="ring")
    tr.start()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SotpyWarning)
        for t in range(8):
            tr.trigger(t)
    assert tr.dropped == 5  # rows of ticks 0..4 were overwritten


def test_overflow_raise():
    tr, _ = _tracer(bufferSize=2, overflow="raise")
    tr.start()
    tr.trigger(0)
    tr.trigger(1)
    with pytest.raises(TracerOverflow, match=r"Tracer\(tr\).*2 rows"):
        tr.trigger(2)
    np.testing.assert_array_equal(tr.data()["time"], [0, 1])


def test_bad_overflow_policy_and_buffer_size():
    with pytest.raises(SotpyError, match="overflow"):
        Tracer("bad", overflow="drop")
    assert not pool.hasEntity("bad")
    tr = Tracer("tr")
    with pytest.raises(SotpyError, match="buffer size"):
        tr.setBufferSize(0)
    with pytest.raises(CommandError):
        tr.setBufferSize(2.5)


def test_adding_a_string_signal_is_refused():
    src = TrcInputs("src")
    tr = Tracer("tr")
    with pytest.raises(SignalTypeError, match=r"TrcInputs\(src\)::output\(string\)::text"):
        tr.add(src.text)
    with pytest.raises(SignalTypeError, match=r"TrcInputs\(src\)::input\(string\)::label"):
        tr.add("src.label")
    assert tr.trigger.dependencies == []
    with pytest.raises(SotpyError, match="no signal"):
        tr.start()


def test_traced_columns_are_fixed_while_rows_are_recorded():
    tr, c = _tracer()
    with pytest.raises(SotpyError, match="already traced"):
        tr.add(c.vec)
    tr.start()
    tr.trigger(0)
    with pytest.raises(SotpyError, match="empty"):
        tr.add("clock.mat")
    tr.empty()
    tr.add("clock.mat")
    tr.trigger(1)
    assert tr.data()["clock.mat"].shape == (1, 4)
    tr.clear()  # SoT's clear: the traced signals go too
    assert tr.columns() == [] and tr.trigger.dependencies == []


def test_dump_refuses_unknown_formats(tmp_path):
    tr, _ = _tracer()
    tr.start()
    tr.trigger(0)
    with pytest.raises(SotpyError, match=r"\.txt"):
        tr.dump(str(tmp_path / "run.txt"))


# -- SoT's files: open, dump(), close -------------------------------------------------
def test_open_dump_close_write_sots_text_files(tmp_path):
    tr, _ = _tracer()
    d = tmp_path / "traces"  # created by open
    tr.open(str(d), "dg_", ".dat")
    files = [d / "dg_vec.dat", d / "dg_h.dat"]  # the label given to add, else the short name
    assert tr.files() == [str(f) for f in files] and all(f.read_text() == "" for f in files)
    tr.start()
    for t in range(3):
        tr.triger(t)  # SoT's spelling: the same row
        tr.trigger(t)
    assert tr.dump() == str(d)  # appends the rows and forgets them
    assert tr.data()["time"].shape == (0,)
    for t in range(3, 5):
        tr.trigger(t)
    tr.close()  # the rows left, then the files are closed
    assert tr.files() == []
    vec = np.loadtxt(files[0], delimiter="\t", ndmin=2)
    h = np.loadtxt(files[1], delimiter="\t", ndmin=2)
    np.testing.assert_array_equal(vec[:, 0], np.arange(5))  # the tick first
    np.testing.assert_array_equal(vec[:, 1:], [vec_ref(t) for t in range(5)])
    np.testing.assert_array_equal(h[:, 1], [0.5 * t for t in range(5)])
    assert files[0].read_text().splitlines()[1].split("\t")[0] == "1"
    with pytest.raises(SotpyError, match=r"Tracer\(tr\)\.dump: no file is open.*open"):
        tr.dump()
    tr.close()  # closing again does nothing


def test_a_signal_added_after_open_gets_its_file_and_clear_closes(tmp_path):
    tr, c = _tracer()
    tr.open(str(tmp_path), "p_", ".txt")
    tr.add(c.mat, "m")
    assert tr.files()[-1] == str(tmp_path / "p_m.txt") and (tmp_path / "p_m.txt").exists()
    tr.start()
    tr.trigger(7)
    tr.dump()
    assert np.loadtxt(tmp_path / "p_m.txt", delimiter="\t").tolist() == [7, 7, 1, 2, -7]
    tr.clear()  # SoT's: the signals go, the files are closed
    assert tr.columns() == [] and tr.files() == []
