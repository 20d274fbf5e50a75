r"""Gradual activation and deactivation of tasks and constraints (ORCA's life cycle).

States and transitions (``dt`` the control period, ``T`` the ramp duration)::

    inactive --activate()--> activating --(ramp reaches 1)--> active
    active --deactivate()--> deactivating --(ramp reaches 0)--> inactive

The ramp ``r`` goes linearly from 0 to 1 in ``T`` seconds (``r += dt / T`` each tick;
``T = 0``: one tick; a value within 1e-9 of 1 is 1, so ``T = 3 dt`` takes exactly 3
ticks) and back down (a value within 1e-9 of 0 is 0). A constraint is enforced while it
is not ``inactive`` (its bounds are not ramped); a contact's wrench bound follows ``r``
(see ``ContactState``).

A task's weight is multiplied by ``ramp_weight(r)``, not by ``r``: with
``s = 3 r^2 - 2 r^3`` (smoothstep),

.. math:: \rho(r) = s \; \epsilon^{1 - s}, \qquad \epsilon = 10^{-6}

(``RAMP_FLOOR``), a weight that rises through six decades, evenly in its logarithm, with
zero slope at both ends. A task's influence on the solution is about ``w / (w + w_o)``
against the weights ``w_o`` it competes with, so a ramp linear in the weight does
almost all its work in the first ticks (at 1/50 of the ramp a weight-10 task already
outweighs a 1e-2 posture 20 to 1); in the logarithm the change is spread over the ramp.
The torque change per tick is bounded besides (:mod:`.solver`: transitions).

Callbacks (set with :meth:`Activatable.setCallback`, names as ORCA's):
``onActivation()`` when ``activate()`` is called, ``onActivated()`` on the tick the ramp
reaches 1, ``onComputeBegin(t, dt)`` and ``onComputeEnd(t, dt)`` around every tick's
update of an object that is not inactive (``t`` in s), ``onDeactivation()`` when
``deactivate()`` is called, ``onDeactivated()`` on the tick the ramp reaches 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from ...errors import SotpyError

__all__ = ["CALLBACKS", "RAMP_FLOOR", "Activatable", "ramp_weight"]

_SNAP = 1e-9  # ramps within this of 0 or 1 are snapped to it

#: The weight factor of a task at the start of its ramp's smooth part (module doc).
RAMP_FLOOR = 1e-6


def ramp_weight(r: float) -> float:
    """The weight factor ``rho(r)`` of a task whose ramp is ``r`` (module doc): 0 at 0,
    1 at 1, increasing, flat at both ends."""
    if r <= 0.0:
        return 0.0
    if r >= 1.0:
        return 1.0
    s = r * r * (3.0 - 2.0 * r)
    return s * RAMP_FLOOR ** (1.0 - s)


CALLBACKS = (
    "onActivation",
    "onActivated",
    "onComputeBegin",
    "onComputeEnd",
    "onDeactivation",
    "onDeactivated",
)


class Activatable:
    """Activation state, ramp and callbacks shared by tasks and constraints."""

    def __init__(self, name: str, ramp_duration: float = 0.0) -> None:
        self.name = name
        self.state = "inactive"
        self.ramp = 0.0
        self.setRampDuration(ramp_duration)
        self.callbacks: dict[str, Callable[..., Any] | None] = dict.fromkeys(CALLBACKS)

    def setRampDuration(self, duration: float) -> None:
        """Duration (s, >= 0, finite) of the activation and deactivation ramps."""
        d = float(duration)
        if not (math.isfinite(d) and d >= 0.0):
            raise SotpyError(f"{self.name}: the ramp duration must be finite and >= 0, got {d}")
        self.ramp_duration = d

    def setCallback(self, event: str, fn: Callable[..., Any] | None) -> None:
        """Set (or clear with ``None``) the callback of ``event`` (one of CALLBACKS)."""
        if event not in CALLBACKS:
            raise SotpyError(
                f"{self.name}: unknown callback {event!r}; expected one of {CALLBACKS}"
            )
        if fn is not None and not callable(fn):
            raise SotpyError(f"{self.name}: the {event} callback must be callable, got {fn!r}")
        self.callbacks[event] = fn

    def _call(self, event: str, *args: Any) -> None:
        fn = self.callbacks[event]
        if fn is not None:
            fn(*args)

    def activate(self) -> None:
        """Start the activation ramp (no effect if active or activating)."""
        if self.state in ("inactive", "deactivating"):
            self.state = "activating"
            self._call("onActivation")

    def deactivate(self) -> None:
        """Start the deactivation ramp (no effect if inactive or deactivating)."""
        if self.state in ("active", "activating"):
            self.state = "deactivating"
            self._call("onDeactivation")

    @property
    def isActivated(self) -> bool:
        return self.state == "active"

    @property
    def isDeactivated(self) -> bool:
        return self.state == "inactive"

    def begin(self, t: float, dt: float) -> bool:
        """Advance the ramp by ``dt`` and call ``onComputeBegin``; False if inactive."""
        state = self.state
        if state == "active":  # the usual case, first
            fn = self.callbacks["onComputeBegin"]
            if fn is not None:
                fn(t, dt)
            return True
        if state == "inactive":
            return False
        self._call("onComputeBegin", t, dt)
        step = 1.0 if self.ramp_duration <= 0.0 else dt / self.ramp_duration
        # a ramp within rounding of its end is at its end (1/3 + 1/3 + 1/3 is not 1)
        if self.state == "activating":
            r = self.ramp + step
            self.ramp = 1.0 if r >= 1.0 - _SNAP else r
        elif self.state == "deactivating":
            r = self.ramp - step
            self.ramp = 0.0 if r <= _SNAP else r
        return True

    def end(self, t: float, dt: float) -> None:
        """Call ``onComputeEnd`` and finish a ramp that reached its end."""
        state = self.state
        if state == "inactive":
            return
        fn = self.callbacks["onComputeEnd"]
        if fn is not None:
            fn(t, dt)
        if state == "active":
            return
        if self.state == "activating" and self.ramp >= 1.0:
            self.state = "active"
            self._call("onActivated")
        elif self.state == "deactivating" and self.ramp <= 0.0:
            self.state = "inactive"
            self._call("onDeactivated")
