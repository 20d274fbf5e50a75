"""``GainAdaptive``: a task gain that grows as the error shrinks (SoT's).

``gain = a exp(-b |e|) + c`` with ``|e|`` the Euclidean norm of the error. SoT's
parameterisation ``set(g0, ginf, slope)``:

- ``g0 = a + c``: the gain at zero error (1/s);
- ``ginf = c``: the gain for a large error (1/s);
- ``slope = a b``: minus the derivative of the gain with respect to ``|e|`` at zero,
  ``d gain / d|e| (0) = -slope``.

So ``a = g0 - ginf``, ``b = slope / a`` (0 when ``g0 = ginf``: a constant gain),
``c = ginf``. A large gain near the target makes the last millimetres converge fast
while a small gain far from it keeps the initial velocities moderate.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CommandError
from ..graph import DOUBLE, VECTOR, Entity, Input, Output, command

__all__ = ["GainAdaptive"]


class GainAdaptive(Entity):
    """``gain = a exp(-b |e|) + c`` of the input ``error`` (see the module doc).

    ``GainAdaptive(name)`` is a constant 0.1 (SoT's default); ``GainAdaptive(name, g)``
    a constant ``g``; ``GainAdaptive(name, g0, ginf, slope)`` as ``set``. Plug
    ``task.error`` into ``error`` and ``gain`` into ``task.controlGain``.
    """

    className = "GainAdaptive"

    error = Input(VECTOR, doc="e: the task's error")

    @Output(DOUBLE, deps=("error",))
    def gain(self, *e: np.ndarray) -> float:
        """a exp(-b |e|) + c (1/s)."""
        if not e or self._b == 0.0:  # a constant (which does not read the error)
            return self._a + self._c
        v = e[0]
        norm = math.sqrt(float(v.dot(v)))  # |e| (inf past 1e154: the gain is then c either way)
        return self._a * math.exp(-self._b * norm) + self._c

    def __init__(self, name: str, *parameters: float) -> None:
        self._a, self._b, self._c = 0.0, 0.0, 0.1
        self._setCoefficients(0.0, 0.0, 0.1)
        if len(parameters) == 1:
            self.setConstant(parameters[0])
        elif len(parameters) == 3:
            self.set(*parameters)
        elif parameters:
            raise CommandError(
                f"{self.className}({name}): expected GainAdaptive(name), (name, gain) or "
                f"(name, valueAt0, valueAtInfty, tanAt0), got {len(parameters)} parameters"
            )

    def _fail(self, cmd: str, message: str) -> CommandError:
        return CommandError(f"{self.className}({self.name}).{cmd}: {message}")

    def _checkGain(self, cmd: str, arg: str, value: float) -> None:
        if not 0.0 <= value < math.inf:
            raise self._fail(cmd, f"argument {arg!r}: expected a finite gain >= 0, got {value}")

    def _setCoefficients(self, a: float, b: float, c: float) -> None:
        self._a, self._b, self._c = a, b, c
        # a constant gain reads nothing: computed once, not at every tick
        constant = b == 0.0 or a == 0.0
        if constant != (not self.gain.dependencies):
            self.gain.setDependencies([] if constant else [self.error])
        self.gain.setReady()

    @command
    def setConstant(self, value: float) -> None:
        """A constant gain ``value`` (1/s)."""
        self._checkGain("setConstant", "value", value)
        self._setCoefficients(0.0, 0.0, value)

    @command
    def set(self, valueAt0: float, valueAtInfty: float, tanAt0: float) -> None:
        """Gain ``valueAt0`` at zero error, ``valueAtInfty`` for a large error, and
        ``d gain / d|e| = -tanAt0`` at zero error (SoT's ``set``)."""
        self._checkGain("set", "valueAt0", valueAt0)
        self._checkGain("set", "valueAtInfty", valueAtInfty)
        a = valueAt0 - valueAtInfty
        if a == 0.0:
            self._setCoefficients(0.0, 0.0, valueAtInfty)
            return
        b = tanAt0 / a
        if not 0.0 < b < math.inf:
            raise self._fail(
                "set",
                f"argument 'tanAt0': with valueAt0 - valueAtInfty = {a:g} the slope must be "
                f"{'> 0' if a > 0 else '< 0'} (the gain goes from valueAt0 to valueAtInfty), "
                f"got {tanAt0}",
            )
        self._setCoefficients(a, b, valueAtInfty)

    @command
    def setByPoint(self, valueAt0: float, valueAtInfty: float, xref: float, p: float) -> None:
        """Gain ``valueAt0`` at zero error, ``valueAtInfty`` for a large error, and at
        ``|e| = xref`` a fraction ``p`` (in (0, 1)) of the way left:
        ``gain(xref) = valueAtInfty + p (valueAt0 - valueAtInfty)``."""
        self._checkGain("setByPoint", "valueAt0", valueAt0)
        self._checkGain("setByPoint", "valueAtInfty", valueAtInfty)
        if not 0.0 < xref < math.inf:
            raise self._fail("setByPoint", f"argument 'xref': expected > 0, got {xref}")
        if not 0.0 < p < 1.0:
            raise self._fail("setByPoint", f"argument 'p': expected a value in (0, 1), got {p}")
        a = valueAt0 - valueAtInfty
        b = 0.0 if a == 0.0 else -math.log(p) / xref
        self._setCoefficients(a, b, valueAtInfty)

    @command
    def getCoefficients(self) -> tuple[float, float, float]:
        """``(a, b, c)`` of ``gain = a exp(-b |e|) + c``."""
        return (self._a, self._b, self._c)

    def value(self, norm: float) -> float:
        """The gain for an error of norm ``norm``."""
        return self._a * math.exp(-self._b * norm) + self._c
