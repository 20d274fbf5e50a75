"""One-tick delays: the explicit way to close a feedback loop inside a tick's graph.

``Delay_of_vector("d")`` has an input ``sin`` and an output ``sout`` with
``sout(t) = sin(t - 1)`` (and ``sout(0)`` = the initial value, set with
``setInitialValue``; ``Delay_of_double`` starts at 0.0, the others raise until set).
``sout`` does not read ``sin`` in the same tick, so ``sin`` may depend on ``sout``
without a cycle.

``sout(t)`` takes ``sin``'s value at ``t - 1`` from ``sin``'s cache, computing it at
``t - 1`` if it was not. If ``sin`` has already been computed at ``t`` or later (so its
value at ``t - 1`` is gone), ``sout`` raises instead of returning a value from the
wrong tick: that happens only when ``sin`` does not depend on ``sout`` and was read
first, which a loop through the delay rules out. Read after a gap of several ticks,
the loop is evaluated at each skipped tick in turn (an accumulator counts every tick).
"""

from __future__ import annotations

from typing import Any

from ..errors import SotpyError
from .command import command
from .entity import Entity, Input, Output
from .signal import FUNCTION, _read
from .types import DOUBLE, MATRIX, VECTOR, SignalType

__all__ = ["Delay_of_double", "Delay_of_matrix", "Delay_of_vector"]


def _delay_class(t: SignalType) -> type[Entity]:
    def sout(self: Any, tick: int) -> Any:
        holder = self.sin._holder()
        if tick <= 0:
            if self._initial is None:
                raise SotpyError(
                    f"{self.sout.name} has no value at tick {tick}: call "
                    f"{self.name}.setInitialValue(...) first"
                )
            return self._initial
        if holder._mode == FUNCTION:
            if holder._time >= tick:
                raise SotpyError(
                    f"{self.sout.name}: cannot give {holder.name} at tick {tick - 1}: it was "
                    f"already computed at tick {holder._time}; read {self.sout.path} first in "
                    "each tick (a Delay is meant to close a loop through its input)"
                )
            # After a gap, catch up one tick at a time: each read needs sout only one
            # tick earlier, already up to date, so the loop never nests more than once.
            for k in range(max(holder._checked + 1, 0), tick - 1):
                _read(holder, k, self.sin)
        return _read(holder, tick - 1, self.sin)

    def setInitialValue(self: Any, value: Any) -> None:
        """Value of ``sout`` at tick 0."""
        self._initial = self.sin._convert(value)
        self.sout.setReady()

    initial = {"double": 0.0, "vector": None, "matrix": None}[t.name]

    def __init__(self: Any, name: str) -> None:  # noqa: N807
        self._initial = initial

    setInitialValue.__annotations__ = {"value": "Any", "return": "None"}
    body = {
        "__doc__": f"One-tick delay of a {t.name}: sout(t) = sin(t - 1), sout(0) = initial value.",
        "__module__": __name__,
        "__init__": __init__,
        "sin": Input(t, doc="value to delay"),
        "sout": Output(t, withTime=True, timeDependent=True, doc="sin one tick earlier")(sout),
        "setInitialValue": command(setInitialValue),
    }
    return type(f"Delay_of_{t.name}", (Entity,), body)


Delay_of_double = _delay_class(DOUBLE)
Delay_of_vector = _delay_class(VECTOR)
Delay_of_matrix = _delay_class(MATRIX)
