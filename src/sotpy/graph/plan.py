"""Compiled evaluation plans and SoT's periodic calls.

A control loop evaluates the same graph every tick. A :class:`Plan` for a set of sink
signals is compiled when the topology changes (:attr:`Pool.version`): the outputs the
sinks depend on are sorted topologically (depth-first with an explicit stack, so a
10,000-signal chain compiles without recursion) and grouped into segments of steps of
the same kind, each run by a loop specialised for it, so that a tick costs one
comparison, one callback call and three stores per signal.

Compiling costs about as much as a few ticks (no code generation: Python's ``compile``
measured 40-60 us per step here, a stall a 1 kHz loop cannot take when a task is pushed
while it runs; the segment loops measured within 15% of generated code).

Each step of the plan is one of two kinds:

* **live**: the output has period 1 and reads, directly or through other live
  outputs, a state signal that its entity writes every tick (``Device.state``) or a
  time-dependent output of period 1. Its dependencies change at
  every tick, so when it is due it is recomputed without looking at them.
* **static**: the output reads only constants. It applies the full lazy rule (recompute
  only if a dependency changed), so a subgraph of constants costs one comparison per
  tick and is recomputed only when a constant is written.

An output with a fusion hook (:meth:`OutputSignal.setPlanFusion`) may be computed by
one step over other signals than its dependencies: the plan orders those sources instead
and skips the signals in between unless another step needs them.

Both kinds recompute a signal at most once per tick and give the values the lazy pull
would give. The plan assumes that a state signal is written at every tick at which the
plan runs (that is what a device does); a live step run at a tick where its state did
not change recomputes the same value.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from ..errors import CycleError, PlugError
from .pool import pool
from .signal import FUNCTION, UNSET, OutputSignal, Signal, _pull, _unplugged

__all__ = ["PeriodicCall", "Plan", "compilePlan"]


class Plan:
    """Evaluate ``sinks`` at a tick with a straight-line function compiled once per
    topology change.

    ``Plan(sinks).run(t)`` brings every sink up to date at tick ``t`` (as reading each
    of them would) and advances the clock to ``t``.
    """

    __slots__ = ("_holders", "_segments", "_sinks", "_version", "steps")

    def __init__(self, sinks: Iterable[Signal]) -> None:
        sinks = tuple(sinks)
        for s in sinks:
            if not isinstance(s, Signal):
                raise PlugError(f"a plan evaluates signals; got {s!r}")
        self._sinks = sinks
        self._version = -1
        self._segments: list[tuple[Callable[[list[Any], int], None], list[Any]]] = []
        self._holders: tuple[Signal, ...] = ()
        self.steps: list[OutputSignal] = []

    @property
    def sinks(self) -> tuple[Signal, ...]:
        """The signals this plan brings up to date."""
        return self._sinks

    def run(self, t: int) -> None:
        """Bring every sink up to date at tick ``t``."""
        if self._version != pool.version:
            self.compile()
        if t > pool.time:
            pool.time = t
        for h in self._holders:
            if h._checked < t:
                break
        else:  # every sink is up to date at t (another plan ran first): reading them
            return  # would compute nothing, and neither does the plan
        for run_segment, items in self._segments:
            run_segment(items, t)

    def compile(self) -> None:
        """Sort the needed outputs and group them into segments.

        Raises:
            UnpluggedError: listing every unset input the sinks depend on.
        """
        order, live, fused = _topological(self._sinks)
        segments: list[tuple[Callable[[list[Any], int], None], list[Any]]] = []
        for s, is_live in zip(order, live, strict=True):
            srcs, fn = fused.get(id(s), (s._srcs, s._fn))
            if not is_live:
                # the lazy rule over the dependencies; a fused output that is not live
                # pulls what its callback reads (the plan ordered only its sources)
                kind, item = (_run_pulled if id(s) in fused else _run_checked), s
            elif s._withTime:
                kind, item = _run_live_n, (s, fn, srcs, True)
            elif len(srcs) == 2:
                kind, item = _run_live_2, (s, fn, srcs[0], srcs[1])
            elif len(srcs) == 1:
                kind, item = _run_live_1, (s, fn, srcs[0])
            else:
                kind, item = _run_live_n, (s, fn, srcs, False)
            if segments and segments[-1][0] is kind:
                segments[-1][1].append(item)
            else:
                segments.append((kind, [item]))
        self._segments = segments
        self._holders = tuple(s._holder() for s in self._sinks)
        self.steps = order
        self._version = pool.version

    def __repr__(self) -> str:
        names = ", ".join(s.path for s in self._sinks)
        return f"<Plan of {len(self.steps)} steps for {names}>"


# Segment runners. A live step of period 1 is recomputed when it has not been at ``t``
# yet; the loops are specialised by arity so that the common steps cost one comparison,
# one call and three stores.
def _run_live_2(items: list[Any], t: int) -> None:
    for s, fn, a, b in items:
        if s._checked < t:
            s._value = fn(a._value, b._value)
            s._time = s._checked = t


def _run_live_1(items: list[Any], t: int) -> None:
    for s, fn, a in items:
        if s._checked < t:
            s._value = fn(a._value)
            s._time = s._checked = t


def _run_live_n(items: list[Any], t: int) -> None:
    for s, fn, srcs, with_time in items:
        if s._checked < t:
            args = [x._value for x in srcs]
            s._value = fn(t, *args) if with_time else fn(*args)
            s._time = s._checked = t


def _run_checked(items: list[Any], t: int) -> None:
    for s in items:
        if s._checked < t:
            s._update(t)


def _run_pulled(items: list[Any], t: int) -> None:
    for s in items:
        if s._checked < t:
            _pull(s, t)


def compilePlan(sinks: Iterable[Signal]) -> Plan:
    """A compiled :class:`Plan` for ``sinks`` (compiles now, so errors show at once)."""
    plan = Plan(sinks)
    plan.compile()
    return plan


def _topological(
    sinks: tuple[Signal, ...],
) -> tuple[list[OutputSignal], list[bool], dict[int, tuple[tuple[Signal, ...], Any]]]:
    """Outputs in FUNCTION mode upstream of ``sinks``, dependencies first, whether each
    is live, and the fused evaluations in force (``id(output) -> (sources, fn)``, see
    :meth:`OutputSignal.setPlanFusion`). Iterative depth-first post-order; raises on
    unset inputs."""
    order: list[OutputSignal] = []
    state: dict[int, int] = {}  # 1: on the stack, 2: done
    missing: list[Signal] = []
    fused: dict[int, tuple[tuple[Signal, ...], Any]] = {}

    def sources(node: OutputSignal) -> tuple[Signal, ...]:
        hook = node._fusion
        if hook is not None and not node._withTime:
            f = hook()
            if f is not None:
                srcs = tuple(s._holder() for s in f[0])  # a plugged input: its source
                fused[id(node)] = (srcs, f[1])
                for s in srcs:  # so that a change upstream outdates the fused output
                    if not any(r is node for r in s._fusedReaders):
                        s._fusedReaders = (*s._fusedReaders, node)
                return srcs
        return node._srcs

    for sink in sinks:
        root = sink._holder()
        if root._mode == UNSET:
            missing.append(root)
            continue
        if root._mode != FUNCTION or id(root) in state:
            continue
        state[id(root)] = 1
        stack = [(root, iter(sources(root)))]  # type: ignore[arg-type]
        while stack:
            node, it = stack[-1]
            for d in it:
                m = d._mode
                if m:
                    if m == UNSET and d not in missing:
                        missing.append(d)
                    continue
                st = state.get(id(d))
                if st == 2:
                    continue
                if st == 1:  # cannot happen through plug(); kept as a guard
                    raise CycleError(f"same-tick cycle through {d.name}", [d.name])
                state[id(d)] = 1
                stack.append((d, iter(sources(d))))  # type: ignore[arg-type]
                break
            else:
                stack.pop()
                state[id(node)] = 2
                order.append(node)
    if missing:
        raise _unplugged(missing, sinks[0] if len(sinks) == 1 else missing[0])
    position = {id(s): i for i, s in enumerate(order)}
    live: list[bool] = []
    for s in order:
        # A periodic output changes only every few ticks: neither it nor what reads
        # only it is live (the outdated rule decides, as for the lazy pull).
        is_live = s.period == 1 and s.timeDependent
        if not is_live and s.period == 1:
            f = fused.get(id(s))
            for src in s._srcs if f is None else f[0]:
                j = position.get(id(src))
                if (j is not None and live[j]) or getattr(src, "_volatile", False):
                    is_live = True
                    break
        live.append(is_live)
    return order, live, fused


class PeriodicCall:
    """SoT's ``before``/``after`` lists: signals brought up to date at each ``run(t)``,
    each one every ``period`` ticks (``t % period == 0``).

    A device runs its ``before`` list before pulling its control and its ``after`` list
    after writing its state; a tracer's ``trigger`` hangs there.
    """

    def __init__(self, owner: str = "") -> None:
        self._owner = owner
        self._signals: dict[int, list[Signal]] = {}
        self._plans: dict[int, Plan] = {}

    def addSignal(self, signal: Signal | str, period: int = 1) -> None:
        """Refresh ``signal`` (a signal or ``"entity.signal"``) every ``period`` ticks."""
        sig = pool.getSignal(signal) if isinstance(signal, str) else signal
        if isinstance(period, bool) or not isinstance(period, int) or period < 1:
            raise PlugError(
                f"{self._owner}: period for {sig.name} must be a positive integer, got {period!r}"
            )
        self.rmSignal(sig, missing_ok=True)
        self._signals.setdefault(period, []).append(sig)
        self._plans[period] = Plan(self._signals[period])

    def addDownsampledSignal(self, signal: Signal | str, period: int) -> None:
        """SoT's name for :meth:`addSignal` with a period."""
        self.addSignal(signal, period)

    def rmSignal(self, signal: Signal | str, missing_ok: bool = False) -> None:
        """Stop refreshing ``signal``."""
        sig = pool.getSignal(signal) if isinstance(signal, str) else signal
        for period, sigs in list(self._signals.items()):
            if any(s is sig for s in sigs):
                sigs[:] = [s for s in sigs if s is not sig]
                if sigs:
                    self._plans[period] = Plan(sigs)
                else:
                    del self._signals[period], self._plans[period]
                return
        if not missing_ok:
            raise PlugError(f"{self._owner}: {sig.name} is not in this periodic call")

    def clear(self) -> None:
        """Remove every signal."""
        self._signals.clear()
        self._plans.clear()

    def list(self) -> list[str]:
        """``path (every k ticks)`` for each signal."""
        return [f"{s.path} (every {k})" for k, sigs in self._signals.items() for s in sigs]

    def run(self, t: int) -> None:
        """Refresh the signals due at tick ``t``."""
        for period, plan in self._plans.items():
            if t % period == 0:
                plan.run(t)

    def __bool__(self) -> bool:
        return bool(self._signals)
