"""Exceptions raised by sotpy.

Every error that a user can cause derives from :class:`SotpyError`. Messages name the
entity, the signal (SoT's ``Class(entity)::input(type)::name`` form) and what was
expected, so that a failure in a running graph can be traced without a debugger. An
operation that raises leaves the graph as it was before the call.
"""

from __future__ import annotations


class SotpyError(Exception):
    """Base class of every sotpy error."""


class SignalTypeError(SotpyError, TypeError):
    """A value or a plug does not match the declared type of a signal."""


class PlugError(SotpyError):
    """A plug was refused (wrong direction, wrong type, would close a cycle)."""


class CycleError(PlugError):
    """A plug or a dependency change would close a same-tick cycle.

    ``cycle`` holds the signal names along the cycle, first one repeated at the end.
    """

    def __init__(self, message: str, cycle: list[str]):
        super().__init__(message)
        self.cycle = cycle


class UnpluggedError(SotpyError):
    """An input signal was read while neither plugged nor set to a constant.

    ``signals`` lists the full names of every unplugged input involved.
    """

    def __init__(self, message: str, signals: list[str]):
        super().__init__(message)
        self.signals = signals


class EntityError(SotpyError):
    """Creating, finding or naming an entity failed."""


class SignalNotFoundError(SotpyError, AttributeError):
    """An entity has no signal of the requested name."""


class CommandError(SotpyError, TypeError):
    """A command was called with missing, extra or ill-typed arguments."""


class FactoryError(SotpyError):
    """An entity class is not known to the factory."""


class GraphvizError(SotpyError):
    """The ``dot`` program is missing or failed to render a graph."""


class TracerOverflow(SotpyError):
    """A tracer buffer is full and the tracer was configured to raise."""


class SolverError(SotpyError, ValueError):
    """A hierarchy given to the solver is malformed (sizes, NaN/inf, lower > upper), or
    its solution is not finite. The message names the level and the row."""


class SimulationError(SotpyError):
    """A simulated device could not step (its state would stop being finite); the
    state is left as it was."""


class LoopError(SotpyError, ValueError):
    """The control loop refused a setting (a period that is not finite, not > 0 or
    rounds to 0 ns; a spin or window out of range) or a request (ticks while it runs or
    while a fault is pending). The message names the loop and the value."""


class RemoteError(SotpyError):
    """The remote interpreter refused a connection, a request or a reply, or the
    connection to it was lost. The message says which."""


class RemoteTimeout(KeyboardInterrupt):
    """Raised in remote code that ran longer than the server's ``exec_timeout``.

    A ``KeyboardInterrupt`` (as Ctrl-C in a local console), so that an
    ``except Exception`` in the remote code does not swallow it."""

    def __init__(self, *args: object) -> None:
        super().__init__(
            *(args or ("remote input interrupted: it ran longer than the server's exec_timeout",))
        )


class ContactError(SotpyError, ValueError):
    """A floor contact setting or an input of the contact simulation is invalid (a
    negative friction coefficient, a non-finite wrench, an unknown frame); nothing is
    changed."""


class RobotError(SotpyError):
    """Loading or describing a robot failed."""


class RobotNotFoundError(RobotError):
    """No robot description of that name; the message lists the known robots."""


class RobotDescriptionError(RobotError):
    """A robot description or its model file is missing, malformed or inconsistent.

    The message names the file and the problem.
    """


class BridgeError(SotpyError):
    """Publishing or subscribing signals across processes failed (:mod:`sotpy.bridge`):
    the middleware is missing or refused a configuration, or a key is misdeclared."""


class StaleSignalError(BridgeError):
    """A subscribed signal was read with no sample, or with a sample older than its age
    limit (``ZenohSubscribe.setMaxAge``), or a lock-step wait timed out. Raised by the
    signal's computation, so a control loop stops the device safely; ``key`` names the
    key expression, ``age`` the age in s (``inf`` before the first sample)."""

    def __init__(self, message: str, key: str, age: float):
        super().__init__(message)
        self.key = key
        self.age = age


class SotpyWarning(UserWarning):
    """Warnings emitted by sotpy (e.g. a tracer buffer that filled up)."""


class BudgetWarning(SotpyWarning):
    """A solver stopped at its iteration or time budget (said once until it converges
    again; the control loop's statistics count every such tick)."""
