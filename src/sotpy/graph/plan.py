"""Compiled evaluation plans and SoT's periodic calls.

A control loop evaluates the same graph every tick. A :class:`Plan` for a set of sink
signals is compiled when the topology changes (:attr:`Pool.version`): the outputs the
sinks depend on are sorted topologically (Kahn-style, with an explicit stack, so a
10,000-signal chain compiles without recursion) and turned into one straight-line
Python function, so that a tick costs one comparison and one callback call per signal.

Each step of the plan is one of two kinds:

* **live**: the output has period 1 and reads, directly or through other live
  outputs, a state signal that its entity writes every tick (``Device.state``) or a
  time-dependent output of period 1. Its dependencies change at
  every tick, so when it is due it is recomputed without looking at them.
* **static**: the output reads only constants. It applies the full lazy rule (recompute
  only if a dependency changed), so a subgraph of constants costs one comparison per
  tick and is recomputed only when a constant is written.

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
from .signal import FUNCTION, UNSET, OutputSignal, Signal, _unplugged

__all__ = ["PeriodicCall", "Plan", "compilePlan"]


class Plan:
    """Evaluate ``sinks`` at a tick with a straight-line function compiled once per
    topology change.

    ``Plan(sinks).run(t)`` brings every sink up to date at tick ``t`` (as reading each
    of them would) and advances the clock to ``t``.
    """

    __slots__ = ("_sinks", "_tick", "_version", "source", "steps")

    def __init__(self, sinks: Iterable[Signal]) -> None:
        sinks = tuple(sinks)
        for s in sinks:
            if not isinstance(s, Signal):
                raise PlugError(f"a plan evaluates signals; got {s!r}")
        self._sinks = sinks
        self._version = -1
        self._tick: Callable[[int], None] | None = None
        self.steps: list[OutputSignal] = []
        self.source = ""

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
        self._tick(t)  # type: ignore[misc]

    def compile(self) -> None:
        """Sort the needed outputs and generate the tick function.

        Raises:
            UnpluggedError: listing every unset input the sinks depend on.
        """
        order, live = _topological(self._sinks)
        lines: list[str] = []
        ns: dict[str, Any] = {}
        index = {id(s): i for i, s in enumerate(order)}
        holders: dict[int, str] = {}
        for i, s in enumerate(order):
            ns[f"s{i}"] = s
        for i, s in enumerate(order):
            if live[i] and s.period == 1:
                args = []
                for src in s._srcs:
                    j = index.get(id(src))
                    if j is not None:
                        name = f"s{j}"
                    elif id(src) in holders:
                        name = holders[id(src)]
                    else:
                        name = holders[id(src)] = f"c{len(holders)}"
                        ns[name] = src
                    args.append(f"{name}._value")
                if s._withTime:
                    args.insert(0, "t")
                ns[f"f{i}"] = s._fn
                lines.append(f" if s{i}._checked < t:")
                lines.append(f"  s{i}._value = f{i}({', '.join(args)})")
                lines.append(f"  s{i}._time = s{i}._checked = t")
            else:
                lines.append(f" if s{i}._checked < t: s{i}._update(t)")
        # The objects the steps use are bound as default arguments: locals are the
        # fastest names CPython has.
        params = "".join(f", {name}={name}" for name in ns)
        source = "\n".join([f"def _tick(t{params}):", *lines, " return None"])
        exec(compile(source, "<sotpy plan>", "exec"), ns)
        self._tick = ns["_tick"]
        self.steps = order
        self.source = source
        self._version = pool.version

    def __repr__(self) -> str:
        names = ", ".join(s.path for s in self._sinks)
        return f"<Plan of {len(self.steps)} steps for {names}>"


def compilePlan(sinks: Iterable[Signal]) -> Plan:
    """A compiled :class:`Plan` for ``sinks`` (compiles now, so errors show at once)."""
    plan = Plan(sinks)
    plan.compile()
    return plan


def _topological(sinks: tuple[Signal, ...]) -> tuple[list[OutputSignal], list[bool]]:
    """Outputs in FUNCTION mode upstream of ``sinks``, dependencies first, and whether
    each is live. Iterative depth-first post-order; raises on unset inputs."""
    order: list[OutputSignal] = []
    state: dict[int, int] = {}  # 1: on the stack, 2: done
    missing: list[Signal] = []
    for sink in sinks:
        root = sink._holder()
        if root._mode == UNSET:
            missing.append(root)
            continue
        if root._mode != FUNCTION or id(root) in state:
            continue
        state[id(root)] = 1
        stack = [(root, iter(root._srcs))]  # type: ignore[attr-defined]
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
                stack.append((d, iter(d._srcs)))  # type: ignore[attr-defined]
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
            for src in s._srcs:
                j = position.get(id(src))
                if (j is not None and live[j]) or getattr(src, "_volatile", False):
                    is_live = True
                    break
        live.append(is_live)
    return order, live


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
