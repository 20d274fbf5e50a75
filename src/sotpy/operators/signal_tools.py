"""Signal tools: finite differences, integration, switches, latches and delays.

=================================  ===================================================
class                              what it computes
=================================  ===================================================
``Derivator_of_Vector``            ``(sin(t) - sin(t')) / ((t - t') dt)``, ``t'`` the
(``_of_double``, ``_of_Matrix``)   previous tick it was computed at; 0 the first time
``Integrator``                     ``q(t) = q(t') (+) (t - t') dt v(t)``: Euler steps
                                   of a velocity, on a Pinocchio model's configuration
                                   space (``setModel``) or in R^n
``SwitchVector``,                  ``sout = sin[selection]`` (or ``sin[boolSelection]``)
``SwitchBoolean``,
``SwitchMatrixHomogeneous``
``Latch``                          a boolean set by ``turnOn`` / ``turnOff``
``Delay_of_double/vector/matrix``  ``sout(t) = sin(t - 1)`` (from :mod:`sotpy.graph`)
=================================  ===================================================

**Ticks.** The graph computes an output at most once per tick, so the memory of the
time-dependent entities (the derivator's previous input, the integrator's
configuration) advances once per tick, however many times the output is read. If the
output is recomputed in the same tick (a constant it depends on was changed), the
memory of the previous tick is used again, not the value just computed. If ticks are
skipped (the output is not read at some ticks), the derivator divides by the elapsed
ticks and the integrator integrates ``v(t)`` over the whole gap (zero-order hold).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3
from ..errors import CommandError, CycleError, SignalTypeError
from ..graph import (
    BOOL,
    DOUBLE,
    INT,
    MATRIX,
    VECTOR,
    Delay_of_double,
    Delay_of_matrix,
    Delay_of_vector,
    Entity,
    Input,
    Output,
    command,
)
from ._util import SelectorInput, check_matrix, check_vector, received, who
from .vector import VariadicOp

__all__ = [
    "Delay_of_double",
    "Delay_of_matrix",
    "Delay_of_vector",
    "Derivator_of_Matrix",
    "Derivator_of_Vector",
    "Derivator_of_double",
    "Integrator",
    "Latch",
    "SwitchBoolean",
    "SwitchMatrixHomogeneous",
    "SwitchVector",
]


def _check_dt(sig: Any, dt: float) -> None:
    if not (math.isfinite(dt) and dt > 0.0):
        raise SignalTypeError(f"{sig.name}: expected a time step > 0 (s), got {dt!r}")


class _TickMemory:
    """The input of the last tick before the current one, and of the current one.

    ``advance(t, x)`` records ``x`` as the value at tick ``t`` and returns the record
    ``(t', x')`` of the latest *earlier* tick (None the first time): a second call at
    the same tick replaces the current value and returns the same earlier record.
    """

    __slots__ = ("cur", "prev")

    def __init__(self) -> None:
        self.prev: tuple[int, Any] | None = None
        self.cur: tuple[int, Any] | None = None

    def before(self, t: int) -> tuple[int, Any] | None:
        """The record of the latest tick earlier than ``t`` (None: there is none)."""
        cur = self.cur
        if cur is None or t < cur[0]:  # never computed, or the clock went back
            return None
        return cur if t > cur[0] else self.prev

    def advance(self, t: int, x: Any) -> tuple[int, Any] | None:
        """Record ``x`` as the value at ``t``; return :meth:`before` ``(t)``."""
        prev = self.before(t)
        self.prev, self.cur = prev, (t, x)
        return prev

    def clear(self) -> None:
        self.prev = self.cur = None


# -- derivators ---------------------------------------------------------------------------
class _Derivator:
    """Mixin: finite difference of ``sin`` over the ticks (SoT's ``Derivator``).

    ``sout(t) = (sin(t) - sin(t')) / ((t - t') dt)`` where ``t'`` is the latest earlier
    tick at which ``sout`` was computed (``t - t' = 1`` when it is read every tick);
    ``sout`` is zero at its first computation (SoT's rule). ``dt`` (s, default 1 as in
    SoT: a difference per tick) is the duration of a tick.
    """

    def __init__(self, name: str) -> None:
        self._memory = _TickMemory()

    def _difference(self, t: int, x: Any, dt: float) -> Any:
        _check_dt(self.dt, dt)  # type: ignore[attr-defined]
        x = np.array(x, dtype=float) if not isinstance(x, float) else x
        prev = self._memory.advance(t, x)
        if prev is None:
            return 0.0 * x
        t0, x0 = prev
        if np.shape(x) != np.shape(x0):
            raise SignalTypeError(
                f"{self.sin.name}: the value changed shape between ticks {t0} and {t} "  # type: ignore[attr-defined]
                f"(from {np.shape(x0)} to {np.shape(x)}): cannot differentiate"
            )
        return (x - x0) / ((t - t0) * dt)

    @command
    def reset(self) -> None:
        """Forget the previous input: the next ``sout`` is zero (as at creation)."""
        self._memory.clear()
        self.sout.setReady()  # type: ignore[attr-defined]


class Derivator_of_Vector(_Derivator, Entity):
    """Finite difference of a vector signal: ``sout = (sin(t) - sin(t')) / ((t - t') dt)``.

    Zero at the first computation; ``dt`` (s per tick, default 1). Units: those of
    ``sin`` per second.
    """

    sin = Input(VECTOR, doc="x, any unit")
    dt = Input(DOUBLE, default=1.0, doc="duration of a tick (s); default 1: per tick")

    @Output(VECTOR, deps=("sin", "dt"), withTime=True, timeDependent=True, doc="dx/dt")
    def sout(self, t: int, x: np.ndarray, dt: float) -> np.ndarray:
        check_vector(self.sin, x)
        return self._difference(t, x, dt)


class Derivator_of_double(_Derivator, Entity):
    """Finite difference of a double signal (see :class:`Derivator_of_Vector`)."""

    sin = Input(DOUBLE, doc="x, any unit")
    dt = Input(DOUBLE, default=1.0, doc="duration of a tick (s); default 1: per tick")

    @Output(DOUBLE, deps=("sin", "dt"), withTime=True, timeDependent=True, doc="dx/dt")
    def sout(self, t: int, x: float, dt: float) -> float:
        return float(self._difference(t, float(x), dt))


class Derivator_of_Matrix(_Derivator, Entity):
    """Finite difference of a matrix signal (see :class:`Derivator_of_Vector`)."""

    sin = Input(MATRIX, doc="X, any unit")
    dt = Input(DOUBLE, default=1.0, doc="duration of a tick (s); default 1: per tick")

    @Output(MATRIX, deps=("sin", "dt"), withTime=True, timeDependent=True, doc="dX/dt")
    def sout(self, t: int, x: np.ndarray, dt: float) -> np.ndarray:
        check_matrix(self.sin, x)
        return self._difference(t, x, dt)


# -- integrator ---------------------------------------------------------------------------
class Integrator(Entity):
    """Integrate a velocity over the ticks (sot-core's ``Integrator``, Euler steps).

    ``configuration(t0) = q0`` at its first computation, then at each later tick ``t``
    (``t'`` the previous one it was computed at)::

        configuration(t) = configuration(t') (+) (t - t') dt velocity(t)

    where ``(+)`` is ``pinocchio.integrate`` on the model given to ``setModel`` (a
    free-flyer's quaternion stays normalised; ``velocity`` has size ``nv``, linear then
    angular velocity of the base in the base frame) or the plain sum in R^n without a
    model. This is the rectangle rule on the current velocity (as SoT's
    ``IntegratorEuler``): ``velocity(t)`` is read in the same tick, so a loop
    ``configuration -> ... -> velocity`` needs a ``Delay_of_vector`` (then
    ``q(t) = q(t-1) + dt v(t-1)``, explicit Euler) or a ``Device``.

    ``q0`` is set by ``setInitialConfig`` (default: the model's neutral configuration,
    or zeros of ``velocity``'s size without a model); calling it restarts the
    integration. ``dt`` (s per tick) has no default: an unset ``dt`` raises.

    sot-core's ``IntegratorEuler*`` transfer-function filters (numerator and
    denominator coefficients) are not provided.
    """

    velocity = Input(VECTOR, doc="v: velocity (size nv with a model), units of q per s")
    dt = Input(DOUBLE, doc="duration of a tick (s)")

    def __init__(self, name: str) -> None:
        self._model: pin.Model | None = None
        self._q0: np.ndarray | None = None
        self._memory = _TickMemory()

    @Output(
        VECTOR,
        deps=("velocity", "dt"),
        withTime=True,
        timeDependent=True,
        doc="q: the integrated configuration (size nq with a model)",
    )
    def configuration(self, t: int, v: np.ndarray, dt: float) -> np.ndarray:
        _check_dt(self.dt, dt)
        model = self._model
        nv = model.nv if model is not None else None
        check_vector(self.velocity, v, nv, "the model's nv" if nv is not None else "")
        prev = self._memory.before(t)
        if prev is None:
            q = self._initial(v)
        else:
            t0, q0 = prev
            step = (t - t0) * dt * v
            if model is not None:
                q = pin.integrate(model, q0, step)
            else:
                if q0.shape != v.shape:
                    raise SignalTypeError(
                        f"{self.velocity.name}: expected a vector of size {q0.shape[0]} (the "
                        f"size of the configuration), received size {v.shape[0]}"
                    )
                q = q0 + step
        self._memory.advance(t, q)
        return q.copy()

    def _initial(self, v: np.ndarray) -> np.ndarray:
        if self._q0 is not None:
            if self._model is None and self._q0.shape != v.shape:
                raise SignalTypeError(
                    f"{self.velocity.name}: expected a vector of size {self._q0.shape[0]} "
                    f"(the size of the initial configuration), received size {v.shape[0]}"
                )
            return self._q0.copy()
        if self._model is not None:
            return pin.neutral(self._model)
        return np.zeros_like(v)

    @command
    def setModel(self, model: pin.Model) -> None:
        """Integrate on ``model``'s configuration space (``pinocchio.integrate``); the
        initial configuration becomes the neutral one. Restarts the integration."""
        self._model = model
        self._q0 = None
        self._restart()

    @command
    def setInitialConfig(self, q: np.ndarray) -> None:
        """Start (again) from ``q`` at the next computation (size nq with a model)."""
        q = np.array(q, dtype=float)
        if q.ndim != 1:
            raise CommandError(
                f"{who(self, 'setInitialConfig')}: expected a vector, got {received(q)}"
            )
        model = self._model
        if model is not None:
            if q.shape[0] != model.nq:
                raise CommandError(
                    f"{who(self, 'setInitialConfig')}: expected a configuration of size "
                    f"nq = {model.nq} for model {model.name!r}, got size {q.shape[0]}"
                )
            if not pin.isNormalized(model, q, 1e-6):
                raise CommandError(
                    f"{who(self, 'setInitialConfig')}: the configuration is not normalised "
                    "(a quaternion or a (cos, sin) pair of norm != 1)"
                )
        self._q0 = q
        self._restart()

    def _restart(self) -> None:
        self._memory.clear()
        self.configuration.setReady()


# -- switches -----------------------------------------------------------------------------
class _Switch(VariadicOp):
    """SoT's ``Switch``: ``sout = sin{k}`` with ``k = selection`` if ``selection`` is
    set (plugged or a constant), else ``k = boolSelection`` (False: 0, True: 1).

    Inputs ``sin0 .. sin{n-1}`` (two by default, ``setSignalNumber(n)``). Every input
    must be set, the unselected ones too: the graph computes what an output depends on
    before choosing (SoT read only the selected one). A selection out of ``0..n-1``
    raises naming it.
    """

    _inDoc = "candidate"

    def _initSwitch(self) -> None:
        onChange = self._selectorChanged
        self._selection = self.addSignal(
            SelectorInput(self, "selection", INT, onChange, doc="k: index of the input copied")
        )
        self._boolSelection = self.addSignal(
            SelectorInput(self, "boolSelection", BOOL, onChange, doc="used when selection is unset")
        )
        self._initVariadic()

    def _leadingDeps(self) -> list[Any]:
        if self._selection.isPlugged:
            return [self._selection]
        if self._boolSelection.isPlugged:
            return [self._boolSelection]
        return [self._selection, self._boolSelection]  # reading raises, naming them

    def _selectorChanged(self, sig: SelectorInput) -> None:
        try:
            self._updateDependencies()
        except CycleError:
            # The plug just made closes a cycle through sout (the plug's own check could
            # not see it: sout did not read this input yet). Undo it, leaving the input
            # unset, and report.
            sig.unplug()
            raise

    def _select(self, k: Any, values: tuple[Any, ...]) -> Any:
        idx = int(k)
        if not 0 <= idx < self._nsin:
            sel = self._selection if self._selection.isPlugged else self._boolSelection
            raise SignalTypeError(
                f"{sel.name}: selection {k!r} is out of range: {self.className}({self.name}) "
                f"has {self._nsin} inputs (sin0 .. sin{self._nsin - 1}; setSignalNumber "
                "changes the number)"
            )
        return values[idx]


class SwitchVector(_Switch, Entity):
    """Copy one of several vectors: ``sout = sin{selection}`` (see ``_Switch``).

    ``sout = sin{k}``, ``k = selection`` if set, else ``int(boolSelection)``.
    """

    _inType = VECTOR

    def __init__(self, name: str) -> None:
        self._initSwitch()

    @Output(VECTOR, timeDependent=False, doc="a copy of the selected input")
    def sout(self, k: Any, *values: np.ndarray) -> np.ndarray:
        return np.array(self._select(k, values), dtype=float)


class SwitchBoolean(_Switch, Entity):
    """Copy one of several booleans: ``sout = sin{k}``, ``k = selection`` if set, else
    ``int(boolSelection)``."""

    _inType = BOOL

    def __init__(self, name: str) -> None:
        self._initSwitch()

    @Output(BOOL, timeDependent=False, doc="the selected input")
    def sout(self, k: Any, *values: bool) -> bool:
        return bool(self._select(k, values))


class SwitchMatrixHomogeneous(_Switch, Entity):
    """Copy one of several placements: ``sout = sin{k}``, ``k = selection`` if set,
    else ``int(boolSelection)``."""

    _inType = SE3

    def __init__(self, name: str) -> None:
        self._initSwitch()

    @Output(SE3, timeDependent=False, doc="a copy of the selected placement")
    def sout(self, k: Any, *values: pin.SE3) -> pin.SE3:
        return self._select(k, values).copy()


# -- latch --------------------------------------------------------------------------------
class Latch(Entity):
    """A boolean memory: ``out`` is True after ``turnOn()``, False after ``turnOff()``
    (False at creation).

    A command takes effect at once: ``out`` read in the same tick gives the new value.
    Reading ``turnOnSout`` (``turnOffSout``) turns the latch on (off) and gives True
    (False), as in sot-core; read them before ``out`` in a tick, or ``out`` is
    recomputed in that tick after the signals that already read it.
    """

    def __init__(self, name: str) -> None:
        self._state = False

    @Output(BOOL, timeDependent=False, doc="the latch's state")
    def out(self) -> bool:
        return self._state

    @Output(BOOL, timeDependent=True, doc="reading it turns the latch on; True")
    def turnOnSout(self) -> bool:
        self._set(True)
        return True

    @Output(BOOL, timeDependent=True, doc="reading it turns the latch off; False")
    def turnOffSout(self) -> bool:
        self._set(False)
        return False

    def _set(self, value: bool) -> None:
        if self._state != value:
            self._state = value
            self.out.setReady()

    @command
    def turnOn(self) -> None:
        """Set ``out`` to True."""
        self._set(True)

    @command
    def turnOff(self) -> None:
        """Set ``out`` to False."""
        self._set(False)
