"""What the dashboard shows and does, without the web server: the graph's snapshot, the
live status, the edits, and the recorder of the plotted signals.

Threads. The loop's thread runs the ticks (holding :attr:`pool.lock
<sotpy.graph.pool.Pool.lock>`); the recorder's hook runs inside each tick (in the
device's ``after`` list, like a tracer's trigger). Everything else here runs in the
server's threads:

* :func:`graphSnapshot` and :func:`applyEdit` hold ``pool.lock`` (between two ticks),
  as the shell does for each input;
* :func:`status` and :meth:`Recorder.since` hold no lock: they read values the tick
  stored (a signal's cached value and tick, ``sot.lastResult``, the controller's ramps)
  and never compute a signal, so they cannot make a tick wait nor see half a
  computation (each attribute they read is replaced whole by the tick).
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SotpyError
from ..graph import INT, Entity, OutputSignal, Plan, checkPlugged, compilePlan
from ..graph.pool import pool
from ..graph.signal import CONSTANT, FUNCTION, PLUGGED, UNSET, InputSignal, Signal
from ..graph.types import _ravel

__all__ = [
    "EditError",
    "Recorder",
    "applyEdit",
    "componentLabels",
    "graphSnapshot",
    "status",
]

log = logging.getLogger("sotpy.dashboard")

#: Types whose values the recorder turns into numbers (``SignalType.to_array``).
_MODES = {FUNCTION: "function", CONSTANT: "constant", UNSET: "unset", PLUGGED: "plugged"}
#: The longest text of a value the page is sent (characters).
_VALUE_TEXT = 400


class EditError(SotpyError):
    """A malformed dashboard request (not JSON, a field missing or of the wrong type)."""


def cached(sig: Signal) -> Any:
    """The value ``sig`` holds now, without computing anything (None if it has none)."""
    return sig._holder()._value


def _mode(sig: Signal) -> str:
    if isinstance(sig, OutputSignal) and sig._mode == CONSTANT and sig._callback is None:
        return "state"  # written by its entity (Device.state)
    return _MODES.get(sig._mode, "?")


def componentLabels(sig: Signal, width: int) -> list[str]:
    """Names of the components of ``sig``'s numeric form (``SignalType.to_array``):
    ``x, y, z`` of an SE3's translation at 3, 7, 11 (its homogeneous matrix, row-major),
    ``[i]`` otherwise, ``[i,j]`` for a matrix."""
    if sig.type.name == "SE3" and width == 16:
        names = [f"R[{i},{j}]" if j < 3 else ".p" + "xyz"[i] for i in range(3) for j in range(4)]
        return [*names, "[3,0]", "[3,1]", "[3,2]", "[3,3]"]
    value = cached(sig)
    if sig.type.name == "matrix" and isinstance(value, np.ndarray) and value.ndim == 2:
        cols = value.shape[1]
        return [f"[{k // cols},{k % cols}]" for k in range(width)]
    return [f"[{k}]" for k in range(width)]


def _width(sig: Signal) -> int | None:
    """The number of components of the value ``sig`` holds (None: no numeric value)."""
    conv = sig.type.to_array
    value = cached(sig)
    if conv is None or value is None:
        return None
    try:
        return int(np.asarray(conv(value)).size)
    except (TypeError, ValueError):
        return None


def valueText(sig: Signal) -> str:
    """The value ``sig`` holds, as short text (numpy's printing, at most 400 characters)."""
    value = cached(sig)
    if value is None:
        return "(no value)"
    if isinstance(value, np.ndarray):
        text = np.array2string(value, precision=4, suppress_small=True, max_line_width=88)
    else:
        text = repr(value)
    return text if len(text) <= _VALUE_TEXT else text[: _VALUE_TEXT - 3] + "..."


def _kind(e: Entity) -> str:
    """A coarse kind of entity, for the page's colours and panels."""
    from ..loop import ControlLoop

    if isinstance(e, ControlLoop):
        return "loop"
    names = {k.__name__ for k in type(e).__mro__}
    for kind, base in (
        ("sot", "SOT"),
        ("controller", "Controller"),
        ("task", "TaskAbstract"),
        ("feature", "FeatureAbstract"),
        ("device", "Device"),
        ("dynamic", "Dynamic"),
    ):
        if base in names:
            return kind
    return "entity"


# ---------------------------------------------------------------------------------------
# The graph
# ---------------------------------------------------------------------------------------
def graphSnapshot(device: Any = None) -> dict[str, Any]:
    """The graph as JSON-ready data (hold ``pool.lock`` around it, as the server does).

    ``entities``: each with ``name``, ``className``, ``kind``, ``commands`` and its
    ``signals`` (``path``, ``name``, ``dir`` in/out, ``type``, ``mode`` (``plugged``,
    ``constant``, ``unset``, ``function``, ``state``), ``source`` (the path it is plugged
    to), ``doc``, ``plottable``, ``width``, ``components``, ``value``); ``edges``: one
    per plugged input (``from`` the source's path, ``to`` the input's); ``clusters``:
    :meth:`Entity.graphClusters` (a solver's tasks, in priority order); ``unplugged``:
    the inputs ``device.control`` depends on that are neither plugged nor set
    (:func:`~sotpy.graph.checkPlugged`), as paths; ``signals``: every path, in the order
    :func:`status` reports the fresh ones; ``version``: :attr:`Pool.version`.
    """
    entities, edges, order = [], [], []
    for e in pool.entities():
        sigs = []
        for s in e.signals():
            width = _width(s)
            src = s.source if isinstance(s, InputSignal) else None
            sigs.append(
                {
                    "path": s.path,
                    "name": s.shortName,
                    "dir": "in" if isinstance(s, InputSignal) else "out",
                    "type": s.type.name,
                    "mode": _mode(s),
                    "source": src.path if src is not None else None,
                    "doc": s.doc,
                    "plottable": s.type.to_array is not None,
                    "width": width,
                    "components": componentLabels(s, width) if width else None,
                    "value": valueText(s),
                }
            )
            order.append(s.path)
            if src is not None:
                edges.append({"from": src.path, "to": s.path})
        entities.append(
            {
                "name": e.name,
                "className": e.className,
                "kind": _kind(e),
                "commands": e.commands(),
                "signals": sigs,
            }
        )
    clusters = [
        {"owner": e.name, "label": label, "members": [m.name for m in members]}
        for e in pool.entities()
        for label, members in e.graphClusters()
    ]
    unplugged: list[str] = []
    control = getattr(device, "control", None)
    if isinstance(control, Signal):
        by_name = {s.name: s.path for e in pool.entities() for s in e.signals()}
        unplugged = [by_name.get(n, n) for n in checkPlugged(control)]
    return {
        "version": pool.version,
        "time": pool.time,
        "entities": entities,
        "edges": edges,
        "clusters": clusters,
        "unplugged": unplugged,
        "control": control.path if isinstance(control, Signal) else None,
        "signals": order,
    }


def signalList() -> list[Signal]:
    """Every signal of the pool, in :func:`graphSnapshot`'s ``signals`` order."""
    return [s for e in pool.entities() for s in e.signals()]


# ---------------------------------------------------------------------------------------
# The live status
# ---------------------------------------------------------------------------------------
def _float(x: Any) -> float | None:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _finite(values: Any) -> list[float | None]:
    return [_float(v) for v in np.asarray(values, dtype=float).ravel()]


def _sotLevels(sot: Any) -> dict[str, Any]:
    """The levels of a SOT and what its solver reported at the last tick
    (``sot.lastResult``, a ``HierarchyResult``; every attribute optional)."""
    names = list(sot.list())
    res = getattr(sot, "lastResult", None)
    residuals = getattr(res, "residuals", None)
    ranks = getattr(res, "ranks", None)
    active = getattr(res, "active", None)
    satisfied = None
    try:
        satisfied = getattr(res, "satisfied", None)
    except Exception:  # a property of a result being rewritten: not shown
        satisfied = None
    n = len(residuals) if residuals is not None else len(names)
    extra = max(0, n - len(names))  # the SOT's own joint-limit level comes first
    labels = ["joint limits"] * extra + names
    levels = []
    for k, name in enumerate(labels):
        task = None if k < extra else _entity(name)
        level: dict[str, Any] = {
            "level": k,
            "task": name,
            "kind": "hard"
            if k < extra
            else ("inequality" if task and task.isInequality else "equality"),
            "rows": None,
            "gain": None,
        }
        if task is not None:
            err = cached(task.error) if task.hasSignal("error") else None
            level["rows"] = int(np.size(err)) if err is not None else None
            if task.hasSignal("controlGain"):
                level["gain"] = _float(cached(task.controlGain))
                level["gainPath"] = task.controlGain.path
        for key, values in (("residual", residuals), ("rank", ranks)):
            level[key] = _float(values[k]) if values is not None and k < len(values) else None
        if satisfied is not None and k < len(satisfied):
            level["satisfied"] = bool(satisfied[k])
        if active is not None and k < len(active):
            rows = np.asarray(active[k]).ravel()
            level["active"] = (
                int(rows.sum()) if rows.dtype == bool else int(rows.size)
            )  # a mask or row indices
            level["activeRows"] = (np.flatnonzero(rows) if rows.dtype == bool else rows)[
                :20
            ].tolist()
        levels.append(level)
    out: dict[str, Any] = {"name": sot.name, "levels": levels}
    for key in ("status", "solved", "iterations", "method"):
        value = getattr(res, key, None)
        if value is not None:
            out[key] = value if isinstance(value, (bool, int, str)) else str(value)
    return out


def _controllerTasks(ctrl: Any) -> dict[str, Any]:
    """The torque controller's tasks (weight, level, ramp, state) and constraints,
    read through its public attributes (``ctrl.core.tasks``, ``.constraints``)."""
    core = getattr(ctrl, "core", None)
    tasks, constraints = [], []
    for t in list(getattr(core, "tasks", {}).values()):
        tasks.append(
            {
                "name": t.name,
                "kind": type(t).__name__,
                "level": getattr(t, "level", None),
                "weight": _float(getattr(t, "weight", None)),
                "ramp": _float(getattr(t, "ramp", None)),
                "rampDuration": _float(getattr(t, "ramp_duration", None)),
                "state": getattr(t, "state", None),
            }
        )
    for c in list(getattr(core, "constraints", {}).values()):
        constraints.append(
            {
                "name": c.name,
                "kind": type(c).__name__,
                "ramp": _float(getattr(c, "ramp", None)),
                "state": getattr(c, "state", None),
            }
        )
    found = cached(ctrl.solutionFound) if ctrl.hasSignal("solutionFound") else None
    return {
        "name": ctrl.name,
        "strategy": getattr(core, "strategy", None),
        "solutionFound": None if found is None else bool(found),
        "tasks": tasks,
        "constraints": constraints,
    }


def _entity(name: str) -> Any:
    return pool._entities.get(name)


def status(
    loop: Any, signals: list[Signal], lastTick: int | None = None, stats: Any = None
) -> dict[str, Any]:
    """The live state, without the lock: the loop's (running, tick, statistics, fault),
    which of ``signals`` were computed at the last tick or since (``fresh``: their
    indices), the SOTs' levels and the torque controllers' tasks.

    The last tick is the one whose control the device applied: its state's tick minus
    one (``lastTick`` overrides it). ``stats``: the loop's ``LoopStats`` if already
    read (default: ``loop.stats()``)."""
    device = getattr(loop, "device", None)
    state = getattr(device, "state", None)
    tick = state.time if isinstance(state, Signal) else pool.time
    last = tick - 1 if lastTick is None else lastTick
    # before the first tick nothing was computed "at the last tick"
    fresh = [i for i, s in enumerate(signals) if s._holder()._time >= last] if tick > 0 else []
    out: dict[str, Any] = {
        "tick": tick,
        "time": pool.time,
        "version": pool.version,
        "fresh": fresh,
        "lastTick": last,
    }
    if loop is not None:
        stats = loop.stats() if stats is None else stats
        out["loop"] = {
            "name": loop.name,
            "running": bool(loop.running),
            "ticks": stats.ticks,
            "dt": loop.dt,
            "rate": _float(stats.rate),
            "tickMean": _float(stats.tick_mean),
            "tickP99": _float(stats.tick_p99),
            "tickMax": _float(stats.tick_max),
            "latencyP99": _float(stats.latency_p99),
            "misses": stats.misses,
            "skipped": stats.skipped,
            "fault": stats.fault,
        }
    sots, ctrls = [], []
    for e in pool.entities():
        kind = _kind(e)
        try:
            if kind == "sot":
                sots.append(_sotLevels(e))
            elif kind == "controller":
                ctrls.append(_controllerTasks(e))
        except Exception as exc:  # a solver being rewritten: say so, keep the rest
            log.debug("status of %s failed: %r", e.name, exc)
            (sots if kind == "sot" else ctrls).append({"name": e.name, "error": repr(exc)})
    out["sots"] = sots
    out["controllers"] = ctrls
    return out


# ---------------------------------------------------------------------------------------
# Edits
# ---------------------------------------------------------------------------------------
def _field(msg: dict[str, Any], key: str, kind: type | tuple[type, ...]) -> Any:
    if key not in msg:
        raise EditError(f"dashboard request {msg.get('kind')!r}: the field {key!r} is missing")
    value = msg[key]
    if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
        want = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
        raise EditError(
            f"dashboard request {msg.get('kind')!r}: {key!r} must be a {want}, got "
            f"{type(value).__name__}"
        )
    return value


def parseValue(sig: Signal, text: str) -> Any:
    """The value typed in the page for ``sig``: JSON (``2.5``, ``[0, 1, 2]``, ``true``,
    ``Infinity``; a 4 x 4 list for an SE3), or the text itself for a string signal."""
    try:
        return json.loads(text)
    except ValueError:
        if sig.type.name in ("string", "flag", "any"):
            return text
        raise SotpyError(
            f"{sig.name}: cannot read {text!r} as a value (write a number such as 2.5, a "
            "list such as [0, 1, 2], true or false)"
        ) from None


def applyEdit(msg: Any, recorder: Recorder | None = None) -> dict[str, Any]:
    """Apply one edit from the page, holding ``pool.lock`` (as the shell runs an input),
    and return ``{"ok": True, "result": text}``.

    ``{"kind": "set", "signal": "entity.signal", "text": "2.5"}`` (or ``"value"``: a JSON
    value): set a constant on an input that is not plugged (a plugged input is refused:
    unplug it from the shell); ``{"kind": "call", "entity": name, "command": name,
    "args": [...]}``: run a command (``sot.push``, ``loop.step``, ``ctrl.setTaskWeight``);
    ``{"kind": "plot", "signal": path}`` / ``"unplot"``: record a signal or stop.

    Raises:
        EditError: a malformed request (it is logged by the server).
        SotpyError: the edit was refused; the graph is as it was (the error's message is
            what the page shows).
    """
    if not isinstance(msg, dict):
        raise EditError(f"a dashboard request must be a JSON object, got {type(msg).__name__}")
    kind = _field(msg, "kind", str)
    if kind == "set":
        path = _field(msg, "signal", str)
        with pool.lock:
            sig = pool.getSignal(path)
            if not isinstance(sig, InputSignal):
                raise SotpyError(
                    f"{sig.name}: an output is computed by its entity; the page sets inputs only"
                )
            if sig._mode == PLUGGED:
                raise SotpyError(
                    f"{sig.name} is plugged to {sig.source.name}: setting a constant would "
                    "unplug it; unplug it from the shell if that is what you want"
                )
            value = parseValue(sig, _field(msg, "text", str)) if "text" in msg else msg.get("value")
            sig.value = value
            return {"ok": True, "result": valueText(sig)}
    if kind == "call":
        name = _field(msg, "entity", str)
        cmd = _field(msg, "command", str)
        args = msg.get("args", [])
        if not isinstance(args, list):
            raise EditError(f"dashboard request 'call': 'args' must be a list, got {args!r}")
        with pool.lock:
            entity = pool.getEntity(name)
            result = entity.getCommand(cmd)(*args)
        text = "" if result is None else repr(result)
        return {"ok": True, "result": text[:_VALUE_TEXT]}
    if kind in ("plot", "unplot"):
        if recorder is None:
            raise SotpyError("this dashboard records nothing (no device)")
        path = _field(msg, "signal", str)
        if kind == "plot":
            recorder.add(path)
        else:
            recorder.remove(path)
        return {"ok": True, "result": path}
    raise EditError(f"unknown dashboard request kind {kind!r} (expected set, call, plot or unplot)")


# ---------------------------------------------------------------------------------------
# The recorder
# ---------------------------------------------------------------------------------------
class _Owner:
    """Stands for an entity as the owner of the recorder's hook signal (which is not in
    the pool: the dashboard is a tool beside the graph, and writeGraph does not draw it)."""

    className = "Dashboard"

    def __init__(self, name: str) -> None:
        self.name = name


def _readsWritten(step: OutputSignal) -> bool:
    """Whether ``step`` reads, directly, a signal its entity writes at each tick (a
    device's state): computed after the tick, it would see the next tick's value."""
    return any(getattr(d._holder(), "_volatile", False) for d in step._srcs)


class _Column:
    __slots__ = ("convert", "data", "error", "first", "holder", "plain", "signal")

    def __init__(self, signal: Signal) -> None:
        self.signal = signal
        self.holder = signal._holder()  # the signal holding its value (a plugged input's source)
        self.convert = signal.type.to_array
        self.plain = self.convert is _ravel  # its numeric form is its value, flattened
        self.data: np.ndarray | None = None  # (rows, width), NaN where not recorded
        self.error: str | None = None
        self.first = -1  # the row count when recording started


class Recorder:
    """The last ``seconds`` of the plotted signals, one row per tick, in a ring.

    A hook (an output signal of the dashboard, not in the pool) hangs in the device's
    ``after`` list, like a :class:`~sotpy.graph.Tracer`'s trigger: at each tick it
    reads every recorded signal at the tick (computing it if it is outdated, as a
    tracer does) and stores its numeric form (``SignalType.to_array``) in preallocated
    memory. A signal that raises is not recorded any more (its ``error`` says why) and
    the tick goes on. The server reads new rows with :meth:`since`, without a lock (the
    tick writes a row, then publishes it by moving the row count).

    **After the tick.** With :attr:`loop` set (a dashboard sets it and registers
    :meth:`finishRow` as the loop's idle call), a real-time run records nothing in the
    tick. The loop calls :meth:`finishRow` right after each tick, holding ``pool.lock``,
    and the row of tick ``T`` is made in two idle calls:

    * after tick ``T - 1`` (the state of ``T`` written): the signals of no step (the
      state, a constant) are copied, and those that share no step with the device's
      control (a task's error that the SOT's fused rows never evaluate, a probe on the
      state) are computed at ``T``, from that state;
    * after tick ``T`` (its control computed): the signals that share a step with the
      control are copied from what the tick computed, and their own steps (a task's
      error over the features the control evaluated) are computed at ``T`` from the
      values the tick cached. The row is published then, one tick later.

    Every value is the one a read at ``T`` would give, and no step of a tick is computed
    outside it. When a shared signal's own steps read the state directly (they would see
    the next tick's), every shared signal is recorded in the tick instead: the device's
    ``after`` list runs them at ``T`` (the next tick's control computed then, and not
    again). ``step`` (no idle calls) records the whole row in the tick.

    ``data()`` and ``save()`` give the rows in the tracer's forms (``Tracer.data``,
    ``Tracer.dump``: ``.npz``, ``.csv``; ``saveFiles``: SoT's one text file per signal).
    """

    def __init__(self, name: str, device: Any, seconds: float, dt: float) -> None:
        if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds > 0):
            raise SotpyError(
                f"Dashboard({name}): history must be a number of s > 0, got {seconds!r}"
            )
        self.dt = float(dt)
        self.size = max(2, math.ceil(seconds / self.dt))
        self.seconds = self.size * self.dt
        self.device = device
        self._ticks = np.full(self.size, -1, dtype=np.int64)
        self._count = 0
        self._columns: dict[str, _Column] = {}
        self._active: tuple[_Column, ...] = ()
        self._holders = -1  # the pool's version when each column's holder was found
        self.loop: Any = None  # the ControlLoop whose idle call finishes the rows
        # the row begun and not yet published: (index, tick, the part it waits for:
        # "shared" after the next tick, "late" after this one, and that part's plan and
        # columns as they were when the row began: a plot added since waits for the next)
        self._open: tuple[int, int, str, Plan | None, tuple[_Column, ...]] | None = None
        self._classified = -1  # the pool's version when the columns were grouped
        self._written: tuple[_Column, ...] = ()  # of no step: copied
        self._shared: tuple[_Column, ...] = ()  # sharing a step with the control
        self._late: tuple[_Column, ...] = ()  # sharing none
        self._sharedAfter = False  # shared columns after the tick (else in it)
        self._sharedPlan: Plan | None = None
        self._latePlan: Plan | None = None
        self.hook = OutputSignal(
            _Owner(name), "record", INT, self._record, withTime=True, timeDependent=True,
            doc="rows recorded by the dashboard",
        )  # fmt: skip
        self._attached = False
        self._hooked = False  # the hook is in the device's after list

    # -- the tick's side ------------------------------------------------------------
    def _record(self, t: int) -> int:
        """The hook, at the end of the tick that wrote the state of ``t``."""
        if self._classified != pool.version:
            self._classify()
        loop = self.loop
        if loop is not None and loop.inRealTimeRun:
            if not self._sharedAfter:  # shared columns in the tick, the late ones after
                self._closeOpen()
                i = self._begin(t)
                self._store(self._sharedPlan, self._shared, i, t)
                self._open = (i, t, "late", self._latePlan, self._late)
            return self._count
        # step (no idle calls): the whole row now
        self._closeOpen()
        i = self._begin(t)
        self._store(self._sharedPlan, self._shared, i, t)
        self._store(self._latePlan, self._late, i, t)
        self._count += 1  # publishes the row
        return self._count

    def _begin(self, t: int) -> int:
        """Begin the row of tick ``t`` (its tick, its copied columns); its index."""
        i = self._count % self.size
        self._ticks[i] = t
        self._store(None, self._written, i, t)
        return i

    def _closeOpen(self) -> None:
        """Finish and publish the row begun and not published, if any: the part it waits
        for is computed when the graph still holds that tick's values (``"shared"``: its
        tick just ran; ``"late"``: no tick ran since), else left NaN (a fault, a stop:
        never a later tick's values under its tick)."""
        if self._open is None:
            return
        i, t, part, plan, columns = self._open
        self._open = None
        held = t + 1 if part == "shared" else t  # the state's time while T's values hold
        if getattr(getattr(self.device, "state", None), "time", held) == held:
            self._store(plan, columns, i, t)
        else:
            for c in columns:
                if c.data is not None:
                    c.data[i] = np.nan
        self._count += 1  # publishes the row

    def finishRow(self) -> None:
        """The loop's idle call, between two ticks of a real-time run (see
        :class:`Recorder`): finish and publish the waiting row, and begin the next one
        (when the shared signals are recorded after the tick). While it makes the rows,
        the hook is out of the device's ``after`` list (it would have nothing to do in
        the tick); the call at the run's end puts it back, for ``step``."""
        with pool.lock:  # as a tick: no edit seen half done
            loop = self.loop
            if loop is None or not loop.inRealTimeRun:  # the run ended: ticks may follow
                self._hook(True)  # without idle calls (the waiting row: the next hook)
                return
            if self._classified != pool.version:
                self._classify()
            self._closeOpen()
            self._hook(not self._sharedAfter)
            if not self._sharedAfter:
                return
            state = getattr(self.device, "state", None)
            t = getattr(state, "time", None)
            if not isinstance(t, int) or t < 0:
                return
            last = self._count - 1
            if last >= 0 and self._ticks[last % self.size] >= t:
                return  # this tick's row was made (in the tick, before an edit moved the split)
            i = self._begin(t)
            self._store(self._latePlan, self._late, i, t)
            self._open = (i, t, "shared", self._sharedPlan, self._shared)

    def _store(self, plan: Plan | None, columns: tuple[_Column, ...], i: int, t: int) -> None:
        """Bring ``columns`` up to date at ``t`` (``plan``: their compiled steps) and copy
        their values into row ``i``."""
        if plan is not None:
            try:  # the recorded signals, with the tick's compiled steps (fused rows)
                plan.run(t)
            except Exception:  # the reads below find the signal that raises
                self._replan()
        if self._holders != pool.version:  # a plug changed: who holds each value
            for c in self._active:
                c.holder = c.signal._holder()
            self._holders = pool.version
        for c in columns:
            data = c.data
            if c.error is not None:
                if data is not None:
                    data[i] = np.nan
                continue
            h = c.holder
            if c.plain and t <= h._checked:  # up to date (the plan computed it): read as is
                v = h._value
                if (
                    type(v) is np.ndarray
                    and v.dtype == np.float64
                    and v.ndim == 1
                    and data is not None
                    and v.shape[0] == data.shape[1]
                ):
                    data[i] = v  # the common case: a vector of floats, copied
                    continue
            try:
                v = c.signal(t)
                a = np.asarray(c.convert(v), dtype=np.float64).ravel()
                if data is None:
                    data = np.full((self.size, a.size), np.nan)
                    c.data = data
                elif a.size != data.shape[1]:
                    raise SotpyError(f"its size changed from {data.shape[1]} to {a.size}")
                data[i] = a
            except Exception as exc:  # never stop the tick for a plot
                c.error = f"{type(exc).__name__}: {exc}"
                self._replan()
                log.warning(
                    "dashboard: stopped recording %s at tick %d: %s", c.signal.name, t, c.error
                )
                if data is not None:
                    data[i] = np.nan

    def _replan(self) -> None:
        """Make the plans again at the next row (the columns or their errors changed)."""
        self._classified = -1

    def _classify(self) -> None:
        """Group the columns and make their compiled :class:`~sotpy.graph.Plan` s (the
        tick's kind of steps, the SOT's fused rows: a value the control computes is not
        computed again): ``written`` (no step: a copy), ``shared`` (a step in common
        with the device's control) and ``late`` (none); and whether the shared ones are
        recorded after the tick (see :class:`Recorder`): with a :attr:`loop`, unless one
        of their own steps reads a signal the tick writes (the state)."""
        self._classified = pool.version
        written, shared, late = [], [], []
        control = getattr(self.device, "control", None)
        used: set[int] | None = None
        if self.loop is not None and control is not None:
            try:
                used = {id(s) for s in compilePlan([control]).steps}
            except Exception:  # an unplugged control: no split (the tick will say why)
                used = None
        after = used is not None
        for c in self._active:
            try:
                steps = compilePlan([c.signal]).steps if c.error is None else []
            except Exception:  # its read in the tick says why
                steps = []
            if not steps:
                written.append(c)
            elif used is None or any(id(s) in used for s in steps):
                shared.append(c)
                own = [s for s in steps if used is None or id(s) not in used]
                if any(_readsWritten(s) for s in own):
                    after = False
            else:
                late.append(c)
        self._written, self._shared, self._late = tuple(written), tuple(shared), tuple(late)
        self._sharedAfter = after
        sinks = [c.signal for c in shared if c.error is None]
        self._sharedPlan = Plan(sinks) if sinks else None
        sinks = [c.signal for c in late if c.error is None]
        self._latePlan = Plan(sinks) if sinks else None

    def _hook(self, on: bool) -> None:
        """Put the hook in the device's ``after`` list or take it out (attached only;
        holding ``pool.lock``)."""
        if self._attached and on != self._hooked:
            if on:
                self.device.after.addSignal(self.hook)
            else:
                self.device.after.rmSignal(self.hook, missing_ok=True)
            self._hooked = on

    # -- configuration (server threads, holding pool.lock) ------------------------
    def attach(self) -> None:
        """Hang the hook in the device's ``after`` list."""
        after = getattr(self.device, "after", None)
        if after is None:
            raise SotpyError(
                f"{self.hook.entity.name}: the device {self.device!r} has no 'after' list"
            )
        with pool.lock:
            after.addSignal(self.hook)
            self._attached = self._hooked = True

    def detach(self) -> None:
        """Take the hook out of the device's ``after`` list."""
        if self._attached:
            with pool.lock:
                self._hook(False)
                self._closeOpen()  # a row left waiting for an idle call
                self._attached = False

    def add(self, path: str) -> None:
        """Record the signal at ``path`` (``entity.signal``) from the next tick on."""
        with pool.lock:
            sig = pool.getSignal(path)
            if path in self._columns:
                return
            if sig.type.to_array is None:
                raise SotpyError(f"{sig.name}: {sig.type.name} values have no numeric form to plot")
            c = _Column(sig)
            c.first = self._count
            self._columns[path] = c
            self._active = tuple(self._columns.values())
            self._replan()

    def remove(self, path: str) -> None:
        """Stop recording ``path`` and forget its rows."""
        with pool.lock:
            if self._columns.pop(path, None) is None:
                raise SotpyError(f"dashboard: {path!r} is not recorded")
            self._active = tuple(self._columns.values())
            self._replan()

    def paths(self) -> list[str]:
        """The recorded signals' paths, in the order they were added."""
        return list(self._columns)

    def errors(self) -> dict[str, str]:
        """Why a signal stopped being recorded, by path."""
        return {p: c.error for p, c in self._columns.items() if c.error is not None}

    @property
    def count(self) -> int:
        """Rows recorded since the start (the ring keeps the last ``size``)."""
        return self._count

    # -- reading (no lock) -----------------------------------------------------------
    def _take(self, a: np.ndarray, start: int, end: int, cols: list[int] | None = None) -> Any:
        """Rows ``start .. end - 1`` of the ring ``a`` (its first axis), oldest first, of
        the columns ``cols`` (None: all): a copy made of at most two slices (fancy
        indexing costs several times more, and a page asks 30 times a second)."""
        i, j = start % self.size, end % self.size
        if start == end or i < j:
            n = end - start
            return a[i : i + n].copy() if cols is None else a[i : i + n, cols]
        if cols is None:
            return np.concatenate((a[i:], a[:j]))
        return np.concatenate((a[i:, cols], a[:j, cols]))

    def since(
        self, cursor: int, series: Iterable[tuple[str, list[int] | None]]
    ) -> tuple[int, np.ndarray, list[np.ndarray | None]]:
        """The rows recorded after row ``cursor``: ``(new cursor, ticks, values)``, one
        ``(rows, components)`` array per ``(path, components)`` of ``series`` (None for a
        signal not recorded or not yet known); only the last ``size`` rows exist."""
        end = self._count
        start = max(cursor, end - self.size + 1, 0)
        ticks = self._take(self._ticks, start, end)
        out: list[np.ndarray | None] = []
        for path, comps in series:
            c = self._columns.get(path)
            data = None if c is None else c.data
            if data is None:
                out.append(None)
                continue
            if comps is not None:
                comps = [k for k in comps if k < data.shape[1]]  # the page may ask too many
                if not comps:
                    out.append(None)
                    continue
            out.append(self._take(data, start, end, comps))
        return end, ticks, out

    def data(self) -> dict[str, np.ndarray]:
        """The ring's rows, oldest first, as ``Tracer.data()`` gives them with
        ``setTimeStep(dt)``: ``{"time": (n,) s, "tick": (n,), path: (n, width)}``; rows
        before a signal was added are NaN."""
        end = self._count
        start = max(end - self.size + 1, 0)
        ticks = self._take(self._ticks, start, end)
        out: dict[str, np.ndarray] = {"time": ticks * self.dt, "tick": ticks}
        for path, c in list(self._columns.items()):
            if c.data is None:
                continue
            out[path] = self._take(c.data, start, end)
        return out

    def save(self, path: str | Path) -> str:
        """Write the ring as ``Tracer.dump(path)`` does: ``.npz`` (``time``, ``tick``,
        one array per signal) or ``.csv`` (``time`` then ``label[i]`` columns)."""
        p = Path(path)
        data = self.data()
        labels = [k for k in data if k not in ("time", "tick")]
        if p.suffix == ".npz":
            np.savez(p, **data)
        elif p.suffix == ".csv":
            header = ["time"]
            cols = [data["time"].reshape(-1, 1)]
            for label in labels:
                width = data[label].shape[1]
                header.extend([label] if width == 1 else [f"{label}[{i}]" for i in range(width)])
                cols.append(data[label])
            table = np.hstack(cols) if len(data["time"]) else np.empty((0, len(header)))
            np.savetxt(p, table, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
        else:
            raise SotpyError(f"dashboard: unknown format {p.suffix!r}; use .npz or .csv")
        return str(p)

    def saveFiles(self, dirname: str | Path, prefix: str = "", suffix: str = ".txt") -> list[str]:
        """Write SoT's tracer files, as ``Tracer.open(dirname, prefix, suffix)`` then
        ``dump()``: one file per signal, ``dirname/prefix + shortName + suffix``, one
        line per recorded row (the tick, a tab, the values separated by tabs, 17
        significant digits); the rows before the signal was recorded are left out."""
        d = Path(dirname)
        d.mkdir(parents=True, exist_ok=True)
        data = self.data()
        written = []
        for path, c in list(self._columns.items()):
            if path not in data:
                continue
            keep = ~np.isnan(data[path]).all(axis=1)
            table = np.column_stack((data["tick"][keep], data[path][keep]))
            out = d / f"{prefix}{c.signal.shortName}{suffix}"
            fmt = ["%d"] + ["%.17g"] * data[path].shape[1]
            with out.open("w") as f:
                np.savetxt(f, table, fmt=fmt, delimiter="\t")
            written.append(str(out))
        return written
