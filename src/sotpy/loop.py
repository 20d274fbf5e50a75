"""The control loop: ticks a device at a fixed rate, in a background thread or in yours.

::

    from sotpy.loop import ControlLoop

    loop = ControlLoop("loop", robot.device, 0.001)  # dt = 1 ms: 1 kHz
    loop.start()            # background thread, real-time pacing
    with loop.edit():       # from another thread: an edit no tick sees half done
        plug(sot.control, robot.device.control)
    print(loop.stats())     # tick time, jitter, deadline misses
    loop.stop()
    loop.step(100)          # 100 ticks now, in this thread, as fast as possible
    loop.run(1000)          # 1000 ticks now, in this thread, paced at dt

A tick is ``device.increment(dt)``, run while holding :attr:`pool.lock
<sotpy.graph.pool.Pool.lock>`. Everything that edits the graph from another thread
holds the same lock (the shell and the remote interpreter hold it while they execute
each input; a script uses ``with loop.edit():``), so a tick never sees half an edit
and an edit never interleaves with a tick. Signals do not lock: the cost per tick is
one acquire and release of an uncontended ``RLock`` and a few clock reads
(``BENCHMARKS.md``, "Control loop: pacing").

Pacing
------
Tick ``k`` of a run is due at the absolute deadline ``t0 + k dt`` (``t0`` the start,
``time.perf_counter_ns``), never ``previous end + dt``, so the rate does not drift.
The thread waits for a deadline with ``Event.wait`` until ``spin`` seconds before it
(default 200 us) and then yields (``os.sched_yield``, which releases the GIL and lets
another thread of the CPU run, but does not let the CPU idle) until the deadline:
sleeping alone wakes 50-100 us late on Linux.

**A CPU that never idles.** While the loop sleeps its CPU idles, and the next tick starts
with cold caches (on a virtual machine the host runs something else on the core; on
bare metal the core may enter a deep sleep state that flushes them). With ``spin=dt``
(or more) the thread never sleeps: it yields for the whole period, and each tick runs as
nearly as fast as back-to-back ticks do. Measured on the Talos reach loop (2-core
virtual machine, the loop on a CPU of its own; ``BENCHMARKS.md``, "Control loop: a CPU
that never idles"): median tick 129 to 103 us (94 back to back), p99 286-345 to 211-297
us, deadline misses 11-16 to 4 in 12 s. The price is a whole CPU: give the loop one of
its own (``cpus=``); on a robot, isolate it (``isolcpus``) as real-time setups do.

What is measured (:meth:`ControlLoop.stats`, a :class:`LoopStats`):

* the **tick time**: ``device.increment`` alone, in s (mean, p99, max);
* the **latency** (jitter): how late each tick started after its deadline, in s
  (mean, p99, max), including the wait for the lock when the shell held it;
* a **deadline miss**: a tick that ended after the next tick's deadline (it overran
  its period). Misses are counted, never silent; when the loop falls more than one
  period behind, the missed deadlines are **skipped** (counted in ``skipped``) rather
  than run back to back: the ticks stay on the ``t0 + k dt`` grid, and simulated time
  falls behind real time by ``skipped * dt``.

p99 and the means are over the last ``window`` ticks (default 10,000); max, counts and
the achieved rate (tick starts per second) are over the whole run since ``start``,
``run`` or ``resetStats`` (which may be called while the loop runs: the next tick starts
the new statistics).

The period ``dt`` is checked when the loop is created: a finite number of seconds > 0
that is at least 1 ns once rounded to whole ns (the deadlines are integer ns), else
:class:`~sotpy.errors.LoopError`.

Safe stop on an exception
-------------------------
Whatever a tick raises (an exception of any callback upstream of the control, of the
device's checks, of a ``before``/``after`` signal; also ``SystemExit`` and a Ctrl-C
``KeyboardInterrupt`` that lands inside the tick) stops the loop, is logged on the
``sotpy.loop`` logger and recorded as :attr:`ControlLoop.fault` (a :class:`LoopFault`
naming the tick, the entity and the signal being computed, and the traceback). The
device is then made safe by setting its ``control`` input to a constant (this unplugs
it; the previous source is remembered):

* ``'velocity'`` control: zero velocity (the robot stops where it is);
* ``'acceleration'`` control: the velocity is set to zero (``device.setVelocity``) and
  the control to zero acceleration: the robot holds its position;
* ``'torque'`` control: the last torque computed without error (recorded after each
  good tick); if the fault happens before any good tick, gravity compensation
  ``g(q)`` for a fixed-base robot, or zero torque for a floating base (a floating
  robot cannot be gravity-compensated without its contact forces).

Further ticks (``step``, ``start``) are refused (:class:`~sotpy.errors.LoopError`)
while the fault is pending: fix the graph, then :meth:`ControlLoop.recover` re-plugs
the previous control source (or :meth:`ControlLoop.clearFault` keeps the safe
constant). A background loop's thread ends; the calling thread (the shell) is never
affected. ``step``/``run`` in the calling thread raise :class:`~sotpy.errors.SotpyError`
from the exception, or re-raise a ``KeyboardInterrupt``/``SystemExit`` after the safe
stop (Ctrl-C still interrupts a script).

The garbage collector
---------------------
A real-time run (``start``, ``run``) collects the young generations before its first
tick and then freezes the heap (:func:`frozenHeap`: ``gc.freeze``), until it ends: the
collector's passes during the run scan only the objects the ticks allocate, not the
graph, the models and the libraries built before. (A full collection would take 77 ms
on a Talos process and delay the first tick by as much; what is garbage in the oldest
generation waits for the end of the run.) Without it, a Talos torque-level run (138,000
tracked objects) paid a pass of the middle generation about every 300 ticks, 1.6 ms
each, and once a pass of the oldest one of 74 ms; frozen, the passes take 13 to 34 us.
``step`` (as fast as possible, often one tick at a time from a shell) leaves the
collector as it is.

CPUs
----
``ControlLoop(..., cpus={3})`` runs the background thread on those CPUs only (Linux's
``sched_setaffinity``; the calling thread of ``step``/``run`` is left as it is). Other
programs running beside the loop (a browser showing the dashboard, a viewer, a compiler)
slow its ticks when the OS puts them on the loop's CPU: they take the CPU during a tick
and evict the tick's data from its caches between two. On a 2-core machine, headless
Chromium drawing the dashboard's plots made the Talos reach loop's median tick 1.44 to
1.49 times longer when it could run anywhere, 1.00 to 1.02 times when the loop had a CPU
of its own (``BENCHMARKS.md``, "Dashboard"). :meth:`ControlLoop.otherCpus` names the
CPUs left to the rest: the dashboard's threads and the browser it starts run there. For
a robot, isolate the loop's CPU from the scheduler as well (the kernel's ``isolcpus``),
so that no other program is put on it.

Shutdown
--------
The loop is an entity: ``pool.remove(loop)`` or ``pool.clear()`` stops its thread
(``onRemove``), as ``stop()`` does; the thread is a daemon, joined by ``stop``. The
loop uses its device: ``pool.remove(device)`` is refused while the loop is in the pool
(``pool.remove(loop, device)`` removes both). A loop given a device that is not in the
pool stops at its first tick with a fault. ``stop()`` may be called while holding
``pool.lock`` (from the shell): the thread waits for the lock with a timeout and checks
for a stop request meanwhile.
"""

from __future__ import annotations

import contextlib
import gc
import logging
import math
import numbers
import os
import threading
import time
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import CommandError, EntityError, LoopError, SotpyError
from .graph import Entity, command
from .graph.pool import pool
from .graph.signal import Signal

__all__ = [
    "DEFAULT_SPIN",
    "DEFAULT_WINDOW",
    "ControlLoop",
    "LoopFault",
    "LoopStats",
    "frozenHeap",
    "unlocked",
]

log = logging.getLogger("sotpy.loop")

#: Default time spent yielding (instead of sleeping) before each deadline, in s.
DEFAULT_SPIN = 200e-6
#: Default number of recent ticks over which means and p99 are computed.
DEFAULT_WINDOW = 10_000
_LOCK_POLL = 0.05  # s: how often a thread waiting for pool.lock checks for a stop request

_frozen = 0  # the frozenHeap contexts open (in any thread)
_frozen_lock = threading.Lock()


@contextlib.contextmanager
def frozenHeap() -> Iterator[None]:
    """While open: the heap as it was on entry is frozen (``gc.collect(1)``, the young
    generations, under a millisecond, then ``gc.freeze()``; see the module doc, "The
    garbage collector"). The collector keeps running on what is allocated after; on
    the exit of the last open context, ``gc.unfreeze()`` gives the frozen objects back
    to it. A real-time :class:`ControlLoop` run opens one; a script that ticks a device
    in its own loop at 1 kHz can too::

        with frozenHeap():
            for _ in range(ticks):
                device.increment(dt)
    """
    global _frozen
    with _frozen_lock:
        if _frozen == 0:
            gc.collect(1)
            gc.freeze()
        _frozen += 1
    try:
        yield
    finally:
        with _frozen_lock:
            _frozen -= 1
            if _frozen == 0:
                gc.unfreeze()


@dataclass(frozen=True)
class LoopStats:
    """Statistics of a :class:`ControlLoop` (times in s, rates in Hz).

    ``tick_*``: duration of ``device.increment`` (mean and p99 over the last ``window``
    ticks, max over the run). ``latency_*``: how late ticks started after their
    deadline (real-time runs only; 0 otherwise). ``misses``: ticks that ended after the
    next deadline; ``skipped``: deadlines dropped to catch up. ``rate``: ticks per
    second of wall time, ``(ticks - 1) / (start of the last tick - start of the
    first)`` (``nan`` before the second tick). ``budget_hits``: ticks during which a
    solver (an ``SOT``, a torque ``Controller``) stopped at its iteration or time budget.
    """

    ticks: int
    period: float
    rate: float
    tick_mean: float
    tick_p99: float
    tick_max: float
    latency_mean: float
    latency_p99: float
    latency_max: float
    misses: int
    skipped: int
    running: bool
    realtime: bool
    fault: str | None
    budget_hits: int = 0

    def __str__(self) -> str:
        us = 1e6
        state = "running" if self.running else "stopped"
        lines = [
            f"{state}{' (real time)' if self.realtime else ''}: {self.ticks} ticks, "
            f"period {self.period * 1e3:g} ms ({1 / self.period:g} Hz), achieved "
            f"{self.rate:.1f} Hz",
            f"tick     mean {self.tick_mean * us:8.1f} us  p99 {self.tick_p99 * us:8.1f} us  "
            f"max {self.tick_max * us:8.1f} us",
            f"latency  mean {self.latency_mean * us:8.1f} us  p99 {self.latency_p99 * us:8.1f} "
            f"us  max {self.latency_max * us:8.1f} us",
            f"deadline misses {self.misses}, skipped deadlines {self.skipped},"
            f" solver budget hits {self.budget_hits}",
        ]
        if self.fault:
            lines.append(f"FAULT: {self.fault}")
        return "\n".join(lines)


@dataclass(frozen=True)
class LoopFault:
    """An exception raised during a tick, and what the loop did about it.

    ``tick``: the device's tick; ``entity``/``signal``: the entity (``Class(name)``) and
    the signal (full SoT name) being computed when it was raised, when found (else ``None``);
    ``exception``: the exception; ``traceback``: its formatted traceback; ``safe``:
    what the device was set to.
    """

    tick: int
    entity: str | None
    signal: str | None
    exception: BaseException
    traceback: str
    safe: str

    def __str__(self) -> str:
        where = self.signal or self.entity or "unknown signal"
        return (
            f"tick {self.tick}: {type(self.exception).__name__} in {where}: "
            f"{self.exception}; {self.safe}"
        )


class _RunStats:
    """The statistics of one run (since ``start``, ``run`` or ``resetStats``).

    The loop records each tick into the object ``ControlLoop._stats`` holds at the
    end of that tick (:meth:`ControlLoop._record`); ``resetStats`` replaces the object,
    so a reset while the loop runs never mixes two runs (a tick that ends during the
    reset is counted in the old one). A new per-tick counter is one more field here,
    counted in ``_record`` and reported by ``stats()``.
    """

    __slots__ = (
        "budgetHits",
        "count",
        "firstBegin",
        "lastBegin",
        "latMax",
        "latNs",
        "misses",
        "skipped",
        "tickMax",
        "tickNs",
    )

    def __init__(self, window: int) -> None:
        self.tickNs = np.zeros(window, dtype=np.int64)  # ring of tick durations, ns
        self.latNs = np.zeros(window, dtype=np.int64)  # ring of start latencies, ns
        self.count = 0  # ticks recorded
        self.tickMax = 0
        self.latMax = 0
        self.misses = 0  # ticks that ended after the next deadline
        self.skipped = 0  # deadlines dropped to catch up
        self.firstBegin = self.lastBegin = 0  # perf_counter_ns of the first, last tick
        self.budgetHits = 0  # ticks during which a solver stopped at its budget


def _locate(tb: Any) -> tuple[str | None, str | None]:
    """(entity, signal) of the innermost frame of ``tb`` computing a signal."""
    entity = signal = None
    frames = [f for f, _ in traceback.walk_tb(tb)]
    for frame in reversed(frames):
        loc = frame.f_locals
        for key in ("self", "s", "node", "root", "h"):
            obj = loc.get(key)
            if isinstance(obj, Signal):
                return f"{obj.entity.className}({obj.entity.name})", obj.name
        obj = loc.get("self")
        if entity is None and isinstance(obj, Entity):
            entity = f"{obj.className}({obj.name})"
            if obj.hasSignal(frame.f_code.co_name):
                signal = obj.signal(frame.f_code.co_name).name
                return entity, signal
    return entity, signal


@contextlib.contextmanager
def unlocked() -> Iterator[None]:
    """``with unlocked(): time.sleep(1)``: release :attr:`pool.lock` for the block.

    The shell and the remote interpreter hold ``pool.lock`` while they run an input, so
    the loop does not tick meanwhile; a long input (a wait, a plot) that does not edit
    the graph can let it tick. Restores the lock (and its recursion depth) after.
    Does nothing if the calling thread does not hold the lock.
    """
    lock = pool.lock
    if not lock._is_owned():  # type: ignore[attr-defined]
        yield
        return
    saved = lock._release_save()  # type: ignore[attr-defined]
    try:
        yield
    finally:
        lock._acquire_restore(saved)  # type: ignore[attr-defined]


def _checkedCpus(who: str, cpus: Iterable[int] | None) -> frozenset[int] | None:
    """``cpus`` as a set of CPU numbers of this machine, or None. Whether the process may
    run there (a container's cpuset) is known when the thread starts (``start``)."""
    if cpus is None:
        return None
    if not hasattr(os, "sched_setaffinity"):
        raise LoopError(f"{who}: cpus: this platform cannot pin a thread to CPUs")
    try:
        wanted = list(cpus)
    except TypeError:
        raise LoopError(f"{who}: cpus must be CPU numbers (integers), got {cpus!r}") from None
    if not wanted or not all(isinstance(c, numbers.Integral) and not isinstance(c, bool)
                             for c in wanted):  # fmt: skip
        raise LoopError(f"{who}: cpus must be a non-empty set of CPU numbers, got {cpus!r}")
    out = frozenset(int(c) for c in wanted)
    count = os.cpu_count() or 1
    if not all(0 <= c < count for c in out):
        raise LoopError(
            f"{who}: cpus {sorted(c for c in out if not 0 <= c < count)} are not CPUs of "
            f"this machine (0 to {count - 1})"
        )
    return out


def _sleep_zero() -> None:
    time.sleep(0)


#: Yield the CPU to another thread without letting it idle (releases the GIL).
_YIELD_CPU = getattr(os, "sched_yield", _sleep_zero)


def _isReal(x: Any) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _periodNs(who: str, dt: Any) -> int:
    """``dt`` (s) in whole ns, or LoopError: not a finite number > 0, rounding to 0 ns,
    or longer than a thread can wait (``threading.TIMEOUT_MAX``)."""
    if not (_isReal(dt) and math.isfinite(dt) and dt > 0):
        raise LoopError(f"{who}: the period dt must be a finite number of s > 0, got {dt!r}")
    if dt > threading.TIMEOUT_MAX:
        raise LoopError(
            f"{who}: the period dt = {dt:g} s is longer than a thread can wait "
            f"({threading.TIMEOUT_MAX:g} s)"
        )
    ns = round(dt * 1e9)
    if ns < 1:
        raise LoopError(
            f"{who}: the period dt = {dt!r} s rounds to 0 ns (the loop counts whole ns); "
            "give at least 1e-9 s"
        )
    return ns


class ControlLoop(Entity):
    """Ticks a device (``increment(dt)``) at ``1 / dt`` Hz; see the module doc.

    ``ControlLoop(name, device, dt=0.001, spin=DEFAULT_SPIN, window=DEFAULT_WINDOW)``:
    ``device`` an entity with ``increment(dt)`` (a :class:`~sotpy.dynamics.Device`),
    ``dt`` the period in s (the device's time step and the real-time period), ``spin``
    the time in s spent yielding before each deadline instead of sleeping, ``window``
    the number of recent ticks the means and p99 are computed over, ``cpus`` the CPUs
    the background thread runs on (None: wherever the OS puts it; see the module doc).
    """

    def __init__(
        self,
        name: str,
        device: Any,
        dt: float = 1e-3,
        spin: float = DEFAULT_SPIN,
        window: int = DEFAULT_WINDOW,
        cpus: Iterable[int] | None = None,
    ) -> None:
        who = f"{self.className}({name})"
        if not callable(getattr(device, "increment", None)):
            raise EntityError(f"{who}: expected a device with increment(dt), got {device!r}")
        self._period_ns = _periodNs(who, dt)
        if not (_isReal(spin) and math.isfinite(spin) and spin >= 0):
            raise LoopError(f"{who}: spin must be a finite number of s >= 0, got {spin!r}")
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise LoopError(f"{who}: window must be an integer >= 1, got {window!r}")
        self._cpus = _checkedCpus(who, cpus)
        self._device = device
        self._dt = float(dt)
        self._spin_ns = int(spin * 1e9)
        self._window = window
        self._thread: threading.Thread | None = None
        self._stopEvent = threading.Event()
        self._state = threading.Lock()  # guards _thread and the run bookkeeping
        self._fault: LoopFault | None = None
        self._unplugged: Any = None  # (source or None, constant) before the safe stop
        self._lastTorque: np.ndarray | None = None
        self._realtime = False
        self._pinError: OSError | None = None  # why the thread could not take its CPUs
        self._idleCalls: tuple[tuple[Callable[[], None], int], ...] = ()
        self._inRealTime = False  # a real-time run is in progress (idle calls follow ticks)
        self.resetStats()

    # -- properties ------------------------------------------------------------------
    @property
    def device(self) -> Any:
        """The device this loop ticks."""
        return self._device

    @property
    def dt(self) -> float:
        """The period, in s."""
        return self._dt

    @property
    def spin(self) -> float:
        """The time (s) spent yielding before each deadline instead of sleeping; at least
        ``dt``: the thread never sleeps (its CPU never idles)."""
        return self._spin_ns * 1e-9

    @property
    def cpus(self) -> frozenset[int] | None:
        """The CPUs the background thread runs on (None: not pinned)."""
        return self._cpus

    def otherCpus(self) -> frozenset[int] | None:
        """The CPUs the calling thread may use that are not the loop's: where the threads
        and programs that serve the loop (the dashboard's server, a browser) should run.
        None when the loop is not pinned or when it has every CPU."""
        if self._cpus is None:
            return None
        rest = frozenset(os.sched_getaffinity(0)) - self._cpus
        return rest or None

    @property
    def inRealTimeRun(self) -> bool:
        """Whether a real-time run (``start``, ``run``) is in progress: the idle calls
        (:meth:`addIdleCall`) follow each of its ticks."""
        return self._inRealTime

    def addIdleCall(self, fn: Callable[[], None], every: int = 1) -> None:
        """Call ``fn()`` in the loop's thread after every ``every``-th tick of a real-time
        run (``start``, ``run``), once the tick is over and counted: outside its tick time,
        in the slack before the next deadline, between two ticks; and once more when the
        run ends, after its last tick (:attr:`inRealTimeRun` is then False).

        For what must not run during a tick: a thread of this process that shares the
        GIL with the loop (a dashboard's server) asks to be woken there, so that its
        Python runs while the loop waits; a dashboard's recorder makes its rows there.
        ``fn`` must be short (tens of us at most, or hand the work to another thread: work
        on the loop's CPU between two ticks still slows the next one a little, its
        caches) and must not raise; one that raises is logged and removed."""
        if not callable(fn):
            raise LoopError(f"{self._who('addIdleCall')}: expected a callable, got {fn!r}")
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise LoopError(
                f"{self._who('addIdleCall')}: every must be an integer >= 1, got {every!r}"
            )
        self._idleCalls = (*((f, k) for f, k in self._idleCalls if f != fn), (fn, every))

    def rmIdleCall(self, fn: Callable[[], None]) -> None:
        """Stop calling ``fn`` (see :meth:`addIdleCall`); nothing if it is not called."""
        self._idleCalls = tuple((f, k) for f, k in self._idleCalls if f != fn)

    @property
    def fault(self) -> LoopFault | None:
        """The pending fault (an exception raised in a tick), or None."""
        return self._fault

    @property
    def running(self) -> bool:
        """Whether the background thread runs."""
        th = self._thread
        return th is not None and th.is_alive()

    @property
    def ticks(self) -> int:
        """Ticks run since the last ``resetStats`` (or creation)."""
        return self._stats.count

    # -- commands --------------------------------------------------------------------
    @command
    def start(self, ticks: int | None = None) -> None:
        """Start ticking in a background thread at 1 / dt Hz (real-time pacing)

        ticks: stop after that many ticks (None: until stop()). Refused while running or
        while a fault is pending (see recover). The statistics restart.
        """
        with self._state:
            self._checkCanTick("start")
            if ticks is not None and ticks < 1:
                raise CommandError(f"{self._who('start')}: ticks must be >= 1, got {ticks}")
            self.resetStats()
            self._stopEvent.clear()
            self._realtime = True
            pinned = threading.Event()
            self._pinError = None
            self._thread = threading.Thread(
                target=self._threadMain,
                args=(ticks, pinned),
                name=f"{self.className}({self.name})",
                daemon=True,
            )
            self._thread.start()
            pinned.wait()  # the thread's first act: set its CPUs (or fail to)
            if self._pinError is not None:
                self._thread.join()
                self._thread = None
                raise LoopError(
                    f"{self._who('start')}: cannot run on cpus {sorted(self._cpus or ())}: "
                    f"{self._pinError.strerror or self._pinError} (this process may use "
                    f"{sorted(os.sched_getaffinity(0))})"
                )

    @command
    def stop(self, timeout: float = 5.0) -> None:
        """Stop the background thread (after the tick in progress) and join it

        Idempotent. Safe to call while holding pool.lock (from the shell).
        """
        self._stopEvent.set()
        th = self._thread
        if th is not None and th is not threading.current_thread():
            th.join(timeout)
            if th.is_alive():
                raise SotpyError(
                    f"{self._who('stop')}: the loop thread did not stop within {timeout:g} s "
                    "(a tick is stuck)"
                )
        self._thread = None

    @command
    def wait(self, timeout: float | None = None) -> bool:
        """Wait for the background thread to end (after start(ticks) or a fault)

        Returns whether it has ended.
        """
        th = self._thread
        if th is not None:
            th.join(timeout)
            return not th.is_alive()
        return True

    @command
    def step(self, n: int = 1) -> None:
        """Run n ticks now, in the calling thread, as fast as possible

        Refused while the background thread runs or a fault is pending; a tick that
        raises stops there (safe stop, see the module doc) and raises SotpyError.
        """
        self._runHere("step", n, realtime=False)

    @command
    def run(self, n: int, realtime: bool = True) -> None:
        """Run n ticks now, in the calling thread, paced at dt (realtime) or not

        As step, with real-time pacing by default; the statistics restart.
        """
        self.resetStats()
        self._runHere("run", n, realtime=realtime)

    @command
    def stats(self) -> LoopStats:
        """Tick time, latency (jitter), deadline misses and achieved rate (LoopStats)."""
        st = self._stats  # one run's statistics, even if resetStats runs meanwhile
        n = st.count
        k = min(n, self._window)
        ticks = st.tickNs[:k]
        lat = st.latNs[:k]
        elapsed = st.lastBegin - st.firstBegin
        rate = (n - 1) / (elapsed * 1e-9) if n > 1 and elapsed > 0 else math.nan
        return LoopStats(
            ticks=n,
            period=self._dt,
            rate=rate,
            tick_mean=float(ticks.mean()) * 1e-9 if k else math.nan,
            tick_p99=float(np.percentile(ticks, 99)) * 1e-9 if k else math.nan,
            tick_max=st.tickMax * 1e-9 if k else math.nan,
            latency_mean=float(lat.mean()) * 1e-9 if k else math.nan,
            latency_p99=float(np.percentile(lat, 99)) * 1e-9 if k else math.nan,
            latency_max=st.latMax * 1e-9 if k else math.nan,
            misses=st.misses,
            skipped=st.skipped,
            running=self.running,
            realtime=self._realtime,
            fault=str(self._fault) if self._fault else None,
            budget_hits=st.budgetHits,
        )

    @command
    def resetStats(self) -> None:
        """Forget the statistics (tick count, times, misses); safe while the loop runs."""
        self._stats = _RunStats(self._window)

    @command
    def recover(self) -> None:
        """Clear the pending fault and restore the control source the safe stop replaced

        Re-plugs device.control to the output it was plugged to (or restores the
        constant it held). Fix the cause first: the next tick would raise again.
        """
        if self._fault is None:
            return
        with pool.lock:
            source, constant = self._unplugged
            ctrl = self._device.control
            if source is not None:
                ctrl.plug(source)
            elif constant is not None:
                ctrl.value = constant
            self._fault = None
            self._unplugged = None

    @command
    def clearFault(self) -> None:
        """Clear the pending fault, keeping the safe control constant on the device."""
        self._fault = None
        self._unplugged = None

    @contextlib.contextmanager
    def edit(self) -> Iterator[None]:
        """``with loop.edit(): ...``: hold pool.lock, so no tick runs during the block."""
        with pool.lock:
            yield

    def _holds(self) -> list[Any]:
        # the device it ticks cannot leave the pool while the loop is there
        return [self._device] if isinstance(self.__dict__.get("_device"), Entity) else []

    def onRemove(self) -> None:
        # the entity leaves the pool (pool.remove, pool.clear): the thread must end
        if "_stopEvent" in self.__dict__:
            self.stop()

    # -- the loop --------------------------------------------------------------------
    def _who(self, cmd: str) -> str:
        return f"{self.className}({self.name}).{cmd}"

    def _checkCanTick(self, cmd: str) -> None:
        if self.running:
            raise LoopError(f"{self._who(cmd)}: the loop is running; call stop() first")
        if self._fault is not None:
            raise LoopError(
                f"{self._who(cmd)}: a fault is pending ({self._fault}); fix the graph, then "
                "call recover() (re-plug the control) or clearFault() (keep the safe control)"
            )

    def _runHere(self, cmd: str, n: int, realtime: bool) -> None:
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise CommandError(f"{self._who(cmd)}: expected a number of ticks >= 0, got {n!r}")
        with self._state:
            self._checkCanTick(cmd)
            self._stopEvent.clear()
            self._realtime = realtime
        failure = self._loop(n, realtime) if n else None
        if failure is None:
            return
        if not isinstance(failure, Exception):
            raise failure  # Ctrl-C, SystemExit: after the safe stop, as the caller expects
        raise SotpyError(f"{self._who(cmd)}: {self._fault}") from failure

    def _threadMain(self, ticks: int | None, pinned: threading.Event) -> None:
        try:
            if self._cpus is not None:
                os.sched_setaffinity(0, self._cpus)  # this thread only (Linux)
        except OSError as exc:  # a CPU outside the process's cpuset: start() says so
            self._pinError = exc
            return
        finally:
            pinned.set()
        try:
            self._loop(ticks, True)  # a failure is recorded as the fault and logged
        except BaseException:  # pragma: no cover - _loop catches everything a tick raises
            log.exception("%s: the loop thread failed", self._who("start"))

    def _loop(self, ticks: int | None, realtime: bool) -> BaseException | None:
        """Run ``ticks`` ticks (None: until stopped), on a frozen heap when real-time;
        return what a tick raised (after the safe stop), or None."""
        if not realtime:
            return self._ticks(ticks, realtime)
        self._inRealTime = True
        try:
            with frozenHeap():
                return self._ticks(ticks, realtime)
        finally:
            self._inRealTime = False
            if self._idleCalls:
                self._callIdle(final=True)

    def _ticks(self, ticks: int | None, realtime: bool) -> BaseException | None:
        lock = pool.lock
        clock = time.perf_counter_ns
        stop = self._stopEvent
        increment = self._device.increment
        dt = self._dt
        period = self._period_ns
        spin = self._spin_ns
        yield_cpu = _YIELD_CPU
        torque = self._device.getControlType() == "torque" if self._hasControlType() else False
        version = -1
        deadline = clock()
        done = 0
        while ticks is None or done < ticks:
            if realtime:
                now = clock()
                if now < deadline - spin and stop.wait((deadline - spin - now) * 1e-9):
                    return None
                while clock() < deadline:
                    yield_cpu()
            if stop.is_set():
                return None
            locked = False
            try:
                while not lock.acquire(timeout=_LOCK_POLL):
                    if stop.is_set():
                        return None
                locked = True
                begin = clock()
                if pool.version != version:  # topology changed: is the device still here?
                    version = pool.version
                    self._checkDevice()
                    torque = self._hasControlType() and self._device.getControlType() == "torque"
                if torque:
                    t = max(self._device.state.time, 0)
                hits = pool.budgetHits
                increment(dt)
                if torque:
                    self._lastTorque = np.array(self._device.control(t), dtype=np.float64)
                end = clock()
                if pool.budgetHits != hits:
                    self._stats.budgetHits += 1
            except BaseException as exc:  # SystemExit and Ctrl-C too: the device is made safe
                if not locked:
                    raise  # interrupted while waiting for the lock: no tick ran
                self._safeStop(exc)
                return exc
            finally:
                if locked:
                    lock.release()
            deadline = self._record(begin, end, deadline, period, realtime)
            done += 1
            if self._idleCalls and realtime:
                self._callIdle()
        return None

    def _callIdle(self, final: bool = False) -> None:
        n = self._stats.count
        for fn, every in self._idleCalls:
            if final or n % every == 0:
                try:
                    fn()
                except Exception:  # never stop the loop for it
                    log.exception("%s: idle call %r raised; removed", self._who("start"), fn)
                    self.rmIdleCall(fn)

    def _record(self, begin: int, end: int, deadline: int, period: int, realtime: bool) -> int:
        """Count one tick (``begin``/``end`` in ns) in the current statistics; return the
        next deadline (the missed ones skipped)."""
        st = self._stats
        i = st.count % self._window
        st.tickNs[i] = d = end - begin
        if d > st.tickMax:
            st.tickMax = d
        if realtime:
            st.latNs[i] = lat = begin - deadline
            if lat > st.latMax:
                st.latMax = lat
            deadline += period
            if end > deadline:
                st.misses += 1
                behind = (end - deadline) // period
                if behind:
                    st.skipped += behind
                    deadline += behind * period
        if not st.count:
            st.firstBegin = begin
        st.lastBegin = begin
        st.count += 1
        return deadline

    def _hasControlType(self) -> bool:
        return callable(getattr(self._device, "getControlType", None))

    def _checkDevice(self) -> None:
        dev = self._device
        name = getattr(dev, "name", None)
        if name is not None and not (pool.hasEntity(name) and pool.getEntity(name) is dev):
            raise EntityError(
                f"{self.className}({self.name}): its device {name!r} left the pool; the loop stops"
            )

    def _safeStop(self, exc: BaseException) -> None:
        """Record the fault and make the device safe (called holding pool.lock)."""
        dev = self._device
        try:
            entity, signal = _locate(exc.__traceback__)
        except Exception:  # pragma: no cover - a broken frame: the fault is still recorded
            entity = signal = None
        tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        try:
            safe = self._makeSafe()
        except Exception as inner:  # the device itself is broken: say so, keep going
            safe = f"could not make the device safe: {type(inner).__name__}: {inner}"
        tick = getattr(getattr(dev, "state", None), "time", -1)
        self._fault = LoopFault(tick, entity, signal, exc, tb, safe)
        self._stopEvent.set()
        log.error("%s: %s\n%s", f"{self.className}({self.name})", self._fault, tb)

    def _makeSafe(self) -> str:
        dev = self._device
        if not (self._hasControlType() and hasattr(dev, "control")):
            return "the device has no control input to make safe"
        ctrl = dev.control
        if self._unplugged is None:
            constant = ctrl.value if ctrl.source is None and ctrl.isPlugged else None
            self._unplugged = (ctrl.source, constant)
        kind = dev.getControlType()
        n = dev.getControlSize()
        if kind == "velocity":
            ctrl.value = np.zeros(n)
            return "device.control set to zero velocity (re-plug with recover())"
        if kind == "acceleration":
            dev.setVelocity(np.zeros(dev.model.nv))
            ctrl.value = np.zeros(n)
            return "velocity set to zero and device.control to zero acceleration: holding position"
        if self._lastTorque is not None and self._lastTorque.shape == (n,):
            ctrl.value = self._lastTorque
            return "device.control holds the last torque computed without error"
        if not dev.hasFreeFlyer:
            import pinocchio as pin

            q = dev.state(max(dev.state.time, 0))
            g = pin.computeGeneralizedGravity(dev.model, dev.model.createData(), q)
            ctrl.value = np.asarray(g)[dev.model.nv - n :]
            return "device.control set to gravity compensation g(q) (no good torque yet)"
        ctrl.value = np.zeros(n)
        return "device.control set to zero torque (floating base, no good torque yet): UNSAFE"
