"""Tasks: features stacked, with a gain (equalities) or bounds (inequalities).

The contract a solver reads (``docs/tasks.md``): every task is a :class:`TaskAbstract`
with the outputs

- ``jacobian`` (m x nv): the stacked Jacobians of its features, in the order they were
  added, with the columns not selected by ``controlSelec`` set to zero;
- ``error`` (m): the stacked errors; ``errorTimeDerivative`` (m): the stacked
  ``errordot``;

and either (``isInequality`` false, :class:`Task`)

- ``task`` (m): the target of ``J qdot = task``, ``task = -controlGain * error``
  (``- errorTimeDerivative`` when ``setWithDerivative(True)``),

or (``isInequality`` true, :class:`TaskInequality`)

- ``lower``, ``upper`` (m): bounds ``lower <= J qdot <= upper`` (``-inf``/``+inf``
  where a side is unbounded).

Values are fresh arrays or read-only ones: a solver must not modify them in place.
A task refuses (raises :class:`~sotpy.errors.SotpyError` naming the task and the
feature) a NaN or infinite error or Jacobian, Jacobians with different numbers of
columns, and a feature whose Jacobian and error have different numbers of rows.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np

from ..errors import CommandError, EntityError, SignalTypeError, SotpyError
from ..graph import DOUBLE, MATRIX, VECTOR, Entity, Input, Output, command, pool
from ..graph.signal import Signal
from . import _rowkernels
from .features import FLAGS, FeatureAbstract, Flags
from .rows import ALL_COLUMNS, Gather, RowOp, computedByOwnCallback

__all__ = ["Task", "TaskAbstract", "TaskInequality"]

_EMPTY = np.zeros(0)
_MISSING = object()


def _featureOps(features: list[Any]) -> list[RowOp] | None:
    """The row operations of ``features``, in order; None if one of them has none."""
    ops = []
    for f in features:
        op = f._rowOp()
        if op is None:
            return None
        ops.append(op)
    return ops


def _columns(selec: Flags, n: int) -> np.ndarray | None:
    """The columns ``selec`` keeps among ``n`` as the kernel's ``cols`` (``ALL_COLUMNS``
    for all of them); None when the selection does not fit (the callback says so)."""
    cols = selec._cache.get(n, _MISSING)
    if cols is _MISSING:
        try:
            cols = selec.rows(n)
        except ValueError:
            return None
    return ALL_COLUMNS if cols is None else cols


class TaskAbstract(Entity):
    """Features stacked into one error and one Jacobian; the common part of
    :class:`Task` and :class:`TaskInequality` (see the module doc for the contract).

    Commands: ``add(feature)`` (an entity or its name), ``remove(feature)``,
    ``clear()``, ``list()``, ``display()``, ``setWithDerivative(bool)``,
    ``getWithDerivative()``.
    """

    className = "TaskAbstract"

    #: False: the task gives an equality target ``task``; True: ``lower``/``upper``.
    isInequality: ClassVar[bool] = False

    controlSelec = Input(
        FLAGS,
        default=Flags(True),
        doc="DoFs (columns) the task may use; the others' Jacobian columns are zeroed",
    )

    @Output(VECTOR, timeDependent=False)
    def error(self, *errors: np.ndarray) -> np.ndarray:
        """The features' errors, stacked in the order they were added (size m)."""
        return self._stack("error", errors)

    @Output(MATRIX, timeDependent=False)
    def jacobian(self, controlSelec: Flags, error: np.ndarray, *jacobians: np.ndarray) -> Any:
        """The features' Jacobians, stacked (m x nv); unselected columns zeroed."""
        if len(jacobians) == 1:
            J = jacobians[0]
            n = J.shape[1]
        elif jacobians:
            n = jacobians[0].shape[1]
            for J in jacobians:
                if J.shape[1] != n:
                    self._checkWidths(jacobians)
            J = np.concatenate(jacobians)
        else:
            raise self._emptyError("jacobian")
        if J.shape[0] != error.shape[0]:
            self._checkRows(jacobians)
        # finite iff the sum of squares is (an overflow falls back to the exact test)
        if not math.isfinite(np.vdot(J, J)) and not np.isfinite(J).all():
            raise self._nonFinite("jacobian", jacobians)
        cols = controlSelec._cache.get(n, _MISSING)
        if cols is _MISSING:
            try:
                cols = controlSelec.rows(n)
            except ValueError as exc:
                raise SignalTypeError(f"{self.controlSelec.name}: {exc} (columns)") from None
        if cols is not None:
            J = J * controlSelec.mask(n)  # a copy, unselected columns zero
        return J

    def _rowOps(self) -> list[RowOp] | None:
        """How an SOT writes this task's rows straight into its buffer: its features'
        row operations, then its own (see :mod:`sotpy.tasks.rows`); None here: a task
        class without them is read through its ``jacobian`` and target signals."""
        return None

    @Output(VECTOR, timeDependent=False)
    def errorTimeDerivative(self, *errordots: np.ndarray) -> np.ndarray:
        """The features' ``errordot`` (de/dt at a fixed configuration), stacked."""
        return self._stack("errordot", errordots)

    def _stack(self, what: str, values: tuple[np.ndarray, ...]) -> np.ndarray:
        if len(values) == 1:
            e = values[0]
        elif values:
            e = np.concatenate(values)
        else:
            raise self._emptyError(what)
        if not math.isfinite(e.dot(e)) and not np.isfinite(e).all():
            raise self._nonFinite(what, values)
        return e

    def _checkWidths(self, jacobians: tuple[np.ndarray, ...]) -> None:
        features = self._wired
        n = jacobians[0].shape[1]
        for f, J in zip(features, jacobians, strict=True):
            if J.shape[1] != n:
                raise SotpyError(
                    f"{self.className}({self.name}): the Jacobian of feature {f.name} has "
                    f"{J.shape[1]} columns but that of {features[0].name} has {n}: the "
                    "features of a task must have Jacobians of the same width (nv)"
                )

    def _checkRows(self, jacobians: tuple[np.ndarray, ...]) -> None:
        for f, Jf in zip(self._wired, jacobians, strict=True):
            m = f.error.value.shape[0]
            if Jf.shape[0] != m:
                raise SotpyError(
                    f"{self.className}({self.name}): feature {f.name} has an error of "
                    f"{m} rows but a Jacobian of {Jf.shape[0]} rows"
                )
        raise SotpyError(  # pragma: no cover - the loop finds the feature
            f"{self.className}({self.name}): the Jacobian and the error have different rows"
        )

    def __init__(self, name: str) -> None:
        if type(self) is TaskAbstract:
            raise EntityError(
                f"TaskAbstract({name}): TaskAbstract is abstract; create a Task or a TaskInequality"
            )
        self._features: list[FeatureAbstract] = []
        self._wired: list[FeatureAbstract] = []
        self._withDerivative = False
        self._wire()

    # -- wiring -----------------------------------------------------------------------
    def _wire(self) -> None:
        """Make the outputs read the current features (called when they change)."""
        fs = list(self._features)
        self.error.setDependencies([f.error for f in fs])
        self.jacobian.setDependencies([self.controlSelec, self.error, *[f.jacobian for f in fs]])
        self.errorTimeDerivative.setDependencies([f.errordot for f in fs])
        self._wired = fs
        self._wireOutputs()

    def _wireOutputs(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _withDerivativeDeps(self) -> list[Signal]:
        return [self.errorTimeDerivative] if self._withDerivative else []

    def _change(self, features: list[FeatureAbstract]) -> None:
        """Switch to ``features``; on failure restore the previous list."""
        old = self._features
        self._features = features
        try:
            self._wire()
        except BaseException:
            self._features = old
            self._wire()
            raise

    def _resolve(self, cmd: str, feature: FeatureAbstract | str) -> FeatureAbstract:
        if isinstance(feature, str):
            if not pool.hasEntity(feature):
                known = [e.name for e in pool.entities() if isinstance(e, FeatureAbstract)]
                raise CommandError(
                    f"{self.className}({self.name}).{cmd}: no feature named {feature!r} "
                    f"(features in the pool: {', '.join(known) or 'none'})"
                )
            entity = pool.getEntity(feature)
            if not isinstance(entity, FeatureAbstract):
                raise CommandError(
                    f"{self.className}({self.name}).{cmd}: {entity!r} is not a feature"
                )
            return entity
        return feature

    # -- errors -----------------------------------------------------------------------
    def _emptyError(self, what: str) -> SotpyError:
        return SotpyError(
            f"{self.className}({self.name}): cannot compute {what}: the task has no "
            "feature (add one with add(feature))"
        )

    def _nonFinite(self, what: str, values: tuple[np.ndarray, ...]) -> SotpyError:
        for f, v in zip(self._wired, values, strict=True):
            if not np.isfinite(v).all():
                bad = "NaN" if np.isnan(v).any() else "infinite values"
                return SotpyError(
                    f"{self.className}({self.name}): the {what} of feature {f.name} "
                    f"contains {bad} ({f.signal(what).name}): refused"
                )
        return SotpyError(f"{self.className}({self.name}): the {what} is not finite")

    # -- commands ---------------------------------------------------------------------
    @command
    def add(self, feature: FeatureAbstract | str) -> None:
        """Append ``feature`` (an entity or its name): its rows come after those of the
        features already there."""
        f = self._resolve("add", feature)
        if any(x is f for x in self._features):
            raise CommandError(
                f"{self.className}({self.name}).add: feature {f.name} is already in the task"
            )
        self._change([*self._features, f])

    @command
    def remove(self, feature: FeatureAbstract | str) -> None:
        """Remove ``feature`` (an entity or its name) from the task."""
        f = self._resolve("remove", feature)
        if not any(x is f for x in self._features):
            raise CommandError(
                f"{self.className}({self.name}).remove: feature {f.name} is not in the "
                f"task (features: {', '.join(self.list()) or 'none'})"
            )
        self._change([x for x in self._features if x is not f])

    @command
    def clear(self) -> None:
        """Remove every feature."""
        self._change([])

    @command
    def list(self) -> list[str]:
        """Names of the features, in order."""
        return [f.name for f in self._features]

    @command
    def features(self) -> list[FeatureAbstract]:
        """The features, in order."""
        return [*self._features]

    @command
    def display(self) -> None:
        """Print the task and its features (SoT's layout)."""
        print(self.displayText())

    def displayText(self) -> str:
        """The text :meth:`display` prints."""
        lines = [f"{self.className} {self.name}: ", "--- LIST ---  "]
        lines += [f"-> {f.name}" for f in self._features]
        return "\n".join(lines)

    @command
    def setWithDerivative(self, withDerivative: bool) -> None:
        """Subtract the features' ``errordot`` from the target (feed-forward of a moving
        reference): ``task = -gain e - de/dt|_q``."""
        self._withDerivative = withDerivative
        self._wireOutputs()

    @command
    def getWithDerivative(self) -> bool:
        """Whether the ``errordot`` feed-forward is on."""
        return self._withDerivative


class Task(TaskAbstract):
    """An equality task: ``J qdot = task`` with ``task = -controlGain * error``.

    ``controlGain`` (1/s, default 1.0, >= 0, plug a ``GainAdaptive`` for a gain that
    depends on the error) makes the error decay as ``de/dt = -controlGain e``. With
    ``setWithDerivative(True)``, ``task = -controlGain e - errorTimeDerivative``, which
    compensates a moving reference (``de/dt = J qdot + de/dt|_q``).
    """

    className = "Task"

    controlGain = Input(DOUBLE, default=1.0, doc="lambda: convergence rate (1/s), >= 0")

    @Output(VECTOR, timeDependent=False)
    def task(self, gain: float, error: np.ndarray, *errordot: np.ndarray) -> np.ndarray:
        """Target of J qdot: -controlGain * error (- errordot with the derivative)."""
        if not 0.0 <= gain < math.inf:
            raise SignalTypeError(
                f"{self.controlGain.name}: expected a finite gain >= 0 (1/s), got {gain}"
            )
        t = -gain * error - errordot[0] if errordot else error * -gain
        # finite iff the sum of squares is (an overflow falls back to the exact test)
        if not math.isfinite(t.dot(t)) and not np.isfinite(t).all():
            raise self._nonFiniteTarget(t, gain, error, errordot)
        return t

    def _nonFiniteTarget(
        self, t: np.ndarray, gain: float, error: np.ndarray, errordot: tuple[Any, ...]
    ) -> SotpyError:
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        extra = f", errorTimeDerivative[{i}] = {errordot[0][i]:g}" if errordot else ""
        return SotpyError(
            f"{self.task.name}[{i}] = -controlGain * error is not finite (controlGain = "
            f"{gain:g} 1/s, error[{i}] = {error[i]:g}{extra}): "
            f"refused; lower {self.controlGain.name} or check the features' errors"
        )

    def _wireOutputs(self) -> None:
        self.task.setDependencies([self.controlGain, self.error, *self._withDerivativeDeps()])

    def _rowOps(self) -> list[RowOp] | None:
        """How an SOT writes this task's rows (``J``, ``-controlGain e``) straight into
        its buffer, from its features' inputs (see :mod:`sotpy.tasks.rows`): the
        features' operations, then an ``EQUALITY`` one; None when it must read
        ``jacobian`` and ``task`` (a derivative feed-forward, an output set to a
        constant or given another callback, a feature without an operation)."""
        if (
            self._withDerivative
            or not self._features
            or not computedByOwnCallback(self.error, TaskAbstract.error.fn)
            or not computedByOwnCallback(self.jacobian, TaskAbstract.jacobian.fn)
            or not computedByOwnCallback(self.task, Task.task.fn)
        ):
            return None
        ops = _featureOps(self._features)
        if ops is None:
            return None

        def bind(at: tuple[int, ...]) -> Gather:
            sGain, aCols = at

            known: list[Any] = [None, 0, None]  # the selection, n and its columns

            def gather(v: Any, o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
                selec, gain = v[o], v[o + 1]
                if type(gain) is not float:
                    return False  # the kernel checks its range; the callback says why
                if known[0] is not selec or known[1] != n:
                    known[:] = selec, n, _columns(selec, n)
                if known[2] is None:
                    return False
                scal[sGain] = gain
                args[aCols] = known[2]
                return True

            return gather

        # (gain, columns)
        return [
            *ops,
            RowOp(_rowkernels.EQUALITY, "si", (self.controlSelec, self.controlGain), bind),
        ]


class TaskInequality(TaskAbstract):
    """An inequality task: keep the stacked error within ``[referenceInf,
    referenceSup]``, as bounds on ``J qdot`` over one control period.

    Inputs: ``referenceInf``, ``referenceSup`` (size m, or empty: unbounded on that
    side; entries may be ``-inf``/``+inf``), ``dt`` (the control period, s, > 0),
    ``controlGain`` (``k`` in (0, 1], default 1: the fraction of the distance to a bound
    the error may cover in one period). With ``e`` the error:

    ``lower = k (referenceInf - e) / dt <= J qdot <= k (referenceSup - e) / dt = upper``

    so that after one period ``e + J qdot dt`` stays within the bounds (``k = 1``), or
    approaches them geometrically (``k < 1``, a velocity damper). An error already out
    of its bounds is driven back at the rate ``k / dt``. With
    ``setWithDerivative(True)`` the ``errordot`` of the features is subtracted from
    both bounds. The bounds are on the error, which is the feature's value ``s`` for a
    feature without reference (``FeatureGeneric``, ``FeaturePosture`` with a zero
    posture...).
    """

    className = "TaskInequality"
    isInequality = True

    referenceInf = Input(VECTOR, default=_EMPTY, doc="lower bound on the error (m; empty: none)")
    referenceSup = Input(VECTOR, default=_EMPTY, doc="upper bound on the error (m; empty: none)")
    dt = Input(DOUBLE, doc="control period (s), > 0")
    controlGain = Input(DOUBLE, default=1.0, doc="k in (0, 1]: fraction per period")

    @Output(VECTOR, timeDependent=False)
    def lower(self, *values: Any) -> np.ndarray:
        """Lower bound on J qdot (size m; -inf where unbounded)."""
        return self._bounds(*values)[0]

    @Output(VECTOR, timeDependent=False)
    def upper(self, *values: Any) -> np.ndarray:
        """Upper bound on J qdot (size m; +inf where unbounded)."""
        return self._bounds(*values)[1]

    def _wireOutputs(self) -> None:
        deps = [
            self.referenceInf,
            self.referenceSup,
            self.controlGain,
            self.dt,
            self.error,
            *self._withDerivativeDeps(),
        ]
        self.lower.setDependencies(deps)
        self.upper.setDependencies(deps)

    def _rowOps(self) -> list[RowOp] | None:
        """How an SOT writes this task's rows (``J``, ``lower``, ``upper``) straight into
        its buffers, from its features' inputs (see :mod:`sotpy.tasks.rows`): the
        features' operations, then an ``INEQUALITY`` one; None when it must read
        ``jacobian``, ``lower`` and ``upper`` (a derivative feed-forward, an output set
        to a constant or given another callback, a feature without an operation).
        Anything out of the ordinary (a gain or period out of range, bounds of the
        wrong size, an overflow) makes the program refuse the tick: the SOT then reads
        the signals, whose callbacks name the error."""
        if (
            self._withDerivative
            or not self._features
            or not computedByOwnCallback(self.error, TaskAbstract.error.fn)
            or not computedByOwnCallback(self.jacobian, TaskAbstract.jacobian.fn)
            or not computedByOwnCallback(self.lower, TaskInequality.lower.fn)
            or not computedByOwnCallback(self.upper, TaskInequality.upper.fn)
        ):
            return None
        ops = _featureOps(self._features)
        if ops is None:
            return None
        isfinite = math.isfinite
        inf_ = math.inf
        ndarray = np.ndarray

        def bind(at: tuple[int, ...]) -> Gather:
            sC, aInf, aSup, aCols = at

            # the references, the selection, n and its columns of the last tick
            known: list[Any] = [None, None, None, 0, None]

            def gather(v: Any, o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
                selec, rinf, rsup, k, dt = v[o : o + 5]
                if type(k) is not float or type(dt) is not float or not (0.0 < k < inf_):
                    return False
                if not 0.0 < dt < inf_:
                    return False
                c = k / dt
                if not isfinite(c):
                    return False
                if known[0] is not rinf or known[1] is not rsup:
                    for ref in (rinf, rsup):
                        if type(ref) is not ndarray or ref.ndim != 1 or ref.dtype.char != "d":
                            return False
                    known[0], known[1] = rinf, rsup
                if known[2] is not selec or known[3] != n:
                    known[2:] = selec, n, _columns(selec, n)
                if known[4] is None:
                    return False
                scal[sC] = c
                args[aInf], args[aSup], args[aCols] = rinf, rsup, known[4]
                return True

            return gather

        sources = (
            self.controlSelec,
            self.referenceInf,
            self.referenceSup,
            self.controlGain,
            self.dt,
        )
        # (k / dt, referenceInf, referenceSup, columns)
        return [*ops, RowOp(_rowkernels.INEQUALITY, "svvi", sources, bind)]

    def _bounds(
        self,
        inf: np.ndarray,
        sup: np.ndarray,
        k: float,
        dt: float,
        e: np.ndarray,
        *errordot: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        m = e.shape[0]
        if not 0.0 < dt < np.inf:
            raise SignalTypeError(f"{self.dt.name}: expected a control period > 0 (s), got {dt}")
        if not 0.0 < k < np.inf:
            raise SignalTypeError(
                f"{self.controlGain.name}: expected a gain > 0 (a fraction of the distance "
                f"to the bound per period, usually in (0, 1]), got {k}"
            )
        bounds = []
        for sig, b, fill in ((self.referenceInf, inf, -np.inf), (self.referenceSup, sup, np.inf)):
            if b.shape[0] == 0:
                b = np.full(m, fill)
            elif b.shape != (m,):
                raise SignalTypeError(
                    f"{sig.name}: expected a vector of size {m} (the size of "
                    f"{self.error.name}) or an empty vector, received size {b.shape[0]}"
                )
            bounds.append(b)
        inf, sup = bounds
        # a lower bound of +inf or an upper bound of -inf cannot be met (NaN neither)
        lowerOk, upperOk = inf < np.inf, sup > -np.inf
        for sig, b, ok, free in (
            (self.referenceInf, inf, lowerOk, "-inf"),
            (self.referenceSup, sup, upperOk, "+inf"),
        ):
            if not ok.all():
                i = int(np.flatnonzero(~ok)[0])
                raise SignalTypeError(
                    f"{sig.name}[{i}] = {b[i]}: a bound no error can meet; use {free} for no bound"
                )
        if (inf > sup).any():
            i = int(np.flatnonzero(inf > sup)[0])
            raise SignalTypeError(
                f"{self.className}({self.name}): referenceInf[{i}] = {inf[i]:g} > "
                f"referenceSup[{i}] = {sup[i]:g}: empty interval"
            )
        c = k / dt
        if not math.isfinite(c):
            raise SignalTypeError(
                f"{self.className}({self.name}): controlGain / dt = {k:g} / {dt:g} s is not "
                f"finite ({self.controlGain.name}, {self.dt.name})"
            )
        lo = c * (inf - e)
        up = c * (sup - e)
        if errordot:
            lo -= errordot[0]
            up -= errordot[0]
        # A row with both references infinite stays free (-inf, +inf): it bounds nothing.
        # A finite reference must give a finite bound (an overflow would silently drop it).
        for sig, ref, out in ((self.referenceInf, inf, lo), (self.referenceSup, sup, up)):
            bad = np.isfinite(ref) != np.isfinite(out)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                name = (self.lower if out is lo else self.upper).name
                raise SignalTypeError(
                    f"{name}[{i}] = (controlGain / dt) "
                    f"({sig.shortName}[{i}] - error[{i}]) is not finite (controlGain = {k:g}, "
                    f"dt = {dt:g} s, {sig.shortName}[{i}] = {ref[i]:g}, error[{i}] = "
                    f"{e[i]:g}): refused"
                )
        return lo, up
