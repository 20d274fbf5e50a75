"""Features: an error ``e`` to bring to zero and its Jacobian (SoT's ``sot/core/feature``).

A feature is an entity with the outputs (all features share them, see
:class:`FeatureAbstract`):

- ``error`` (vector, size ``dim``): ``e(q, t)``, the selected rows;
- ``jacobian`` (matrix, ``dim x nv``): ``J = de/dq``, so that ``de/dt = J v + de/dt|_q``
  with ``v`` the robot's tangent velocity (size ``nv``, Pinocchio's convention: a
  free-flyer's linear then angular velocity in the base frame, then the joints);
- ``errordot`` (vector, size ``dim``): ``de/dt|_q``, the rate of change of the error
  due to a moving reference at a fixed configuration (SoT: "derivative of error when
  value.position is constant"); zero when the reference does not move;
- ``dim`` (int): the number of selected rows;

and the input ``selec`` (SoT's flags): which rows of the full error are kept. Flags
are read **left to right**, as in sot-core >= 4.11 (``src/tools/flags.cpp``): character
``i`` selects row ``i``, and rows past the end of the string are not selected. So
``"111000"`` selects the translation rows ``0, 1, 2`` of a pose feature, ``"000111"``
its rotation rows, and ``"11"`` the ``x, y`` rows of a CoM feature. (The SoT before
2020 read them right to left: ``"000111"`` was the translation; scripts written for it
must reverse their strings.) A sequence of booleans (``[True, False, ...]``), a
``numpy`` boolean mask or ``True`` (every row, the default) are accepted too.

The classes, their errors and Jacobians (``docs/tasks.md`` has the derivations):

==========================  ================================================  ==========
class                       full error ``e``                                  rows
==========================  ================================================  ==========
``FeaturePose``             ``(t(M*^-1 M), log3(R*^T R))``                    6
``FeaturePoseSE3``          ``log6(M*^-1 M)``                                 6
``FeaturePoint6d``          ``FeaturePose``'s, the reference a second one     6
``FeatureGeneric``          ``errorIN - reference.errorIN``                   any
``FeaturePosture``          ``difference(q*, q)`` (``q = q* (+) e``)          nv
``FeatureJointLimits``      ``2 (q - l) / (u - l) - 1``                       nv
``FeatureVisualPoint``      ``(x, y) - (x*, y*)``                             2
==========================  ================================================  ==========

Every formula here is tested against finite differences of the error along random
joint velocities (``tests/test_features.py``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import pinocchio as pin

from ..dynamics.types import SE3
from ..errors import CommandError, EntityError, SignalTypeError
from ..graph import (
    DOUBLE,
    INT,
    MATRIX,
    VECTOR,
    Entity,
    Input,
    Output,
    SignalType,
    command,
    plug,
    pool,
)
from ..graph.signal import InputSignal, Signal
from . import _rowkernels
from .rows import CALLBACK_ROWS, Gather, RowOp, callbackOp, computedByOwnCallback

__all__ = [
    "FLAGS",
    "OPTICAL_FROM_XFORWARD",
    "FeatureAbstract",
    "FeatureGeneric",
    "FeatureJointLimits",
    "FeaturePoint6d",
    "FeaturePose",
    "FeaturePoseSE3",
    "FeaturePosture",
    "FeatureVisualPoint",
    "Flags",
    "interactionMatrix",
]

_EMPTY = np.zeros(0)
_MISSING = object()
_NONE = np.zeros(0, dtype=np.intp)  # FeaturePose._split: no row of a block selected


# -- flags ----------------------------------------------------------------------------
class Flags:
    """SoT's selection flags: which rows of a feature (or columns of a task) are kept.

    ``Flags("111000")``: character ``i`` (left to right) selects row ``i``; rows past
    the end take the value ``rest`` (``False`` for a string or a sequence). Spaces are
    ignored. ``Flags(True)`` selects every row, ``Flags(False)`` none;
    ``Flags([True, False])`` and ``Flags(numpy_bool_mask)`` take one boolean per row.

    Flags are immutable; ``f(i)`` is the flag of row ``i`` (SoT's ``operator()``),
    ``~f``, ``f & g`` and ``f | g`` combine them, ``f.set(i, value)`` returns a copy
    with one flag changed, and ``f.rows(n)`` the selected row indices among ``n``.
    """

    __slots__ = ("_bits", "_cache", "_rest")

    def __init__(self, spec: Flags | str | bool | Iterable[Any] = True, rest: bool = False):
        if isinstance(spec, Flags):
            bits, rest = spec._bits, spec._rest
        elif isinstance(spec, (bool, np.bool_)):
            bits, rest = (), bool(spec)
        elif isinstance(spec, str):
            chars = spec.replace(" ", "")
            bad = sorted({c for c in chars if c not in "01"})
            if bad:
                raise ValueError(
                    f"flags {spec!r}: expected a string of '0' and '1' (read left to right: "
                    f"character i selects row i), found {', '.join(map(repr, bad))}"
                )
            bits = tuple(c == "1" for c in chars)
        elif isinstance(spec, (int, float, np.integer, np.floating)):
            raise TypeError(
                f"flags: expected a string such as '111000', a bool or a sequence of bools, "
                f"got the number {spec!r}"
            )
        else:
            try:
                items = list(spec)
            except TypeError:
                raise TypeError(
                    "flags: expected a string such as '111000', a bool or a sequence of "
                    f"bools, got {type(spec).__name__}"
                ) from None
            out = []
            for x in items:
                if isinstance(x, (bool, np.bool_)) or (
                    isinstance(x, (int, np.integer)) and x in (0, 1)
                ):
                    out.append(bool(x))
                else:
                    raise TypeError(f"flags: expected booleans (or 0/1), got {x!r} in {spec!r}")
            bits = tuple(out)
        self._bits: tuple[bool, ...] = bits
        self._rest: bool = bool(rest)
        self._cache: dict[int, np.ndarray | None] = {}

    # -- queries ----------------------------------------------------------------------
    def __call__(self, i: int) -> bool:
        """The flag of row ``i`` (SoT's ``fl(i)``)."""
        return self._bits[i] if i < len(self._bits) else self._rest

    def __len__(self) -> int:
        """Number of explicit flags (rows past them take the ``rest`` value)."""
        return len(self._bits)

    @property
    def rest(self) -> bool:
        """The flag of every row past the explicit ones."""
        return self._rest

    def rows(self, n: int) -> np.ndarray | None:
        """Indices of the selected rows among ``n`` rows; ``None`` when all are.

        Raises:
            ValueError: an explicit flag selects a row ``>= n`` (the flags were written
                for a larger feature).
        """
        try:
            return self._cache[n]
        except KeyError:
            pass
        bits = self._bits
        extra = [i for i in range(n, len(bits)) if bits[i]]
        if extra:
            raise ValueError(
                f"flags {self} select row {extra[0]} but there are only {n} rows "
                f"(rows 0 to {n - 1})"
            )
        mask = [self(i) for i in range(n)]
        if all(mask):
            rows = None
        else:
            rows = np.flatnonzero(mask)
            rows.flags.writeable = False
        self._cache[n] = rows
        return rows

    def mask(self, n: int) -> np.ndarray:
        """The flags of rows ``0..n-1`` as a boolean array."""
        return np.array([self(i) for i in range(n)], dtype=bool)

    def count(self, n: int) -> int:
        """Number of rows selected among ``n``."""
        rows = self.rows(n)
        return n if rows is None else len(rows)

    # -- combinations -----------------------------------------------------------------
    def set(self, i: int, value: bool = True) -> Flags:
        """A copy with the flag of row ``i`` set to ``value``."""
        if i < 0:
            raise ValueError(f"flags: row index must be >= 0, got {i}")
        bits = list(self._bits) + [self._rest] * max(0, i + 1 - len(self._bits))
        bits[i] = bool(value)
        return Flags(bits, rest=self._rest)

    def __invert__(self) -> Flags:
        return Flags([not b for b in self._bits], rest=not self._rest)

    def _combine(self, other: Any, op: Any) -> Flags:
        o = other if isinstance(other, Flags) else Flags(other)
        n = max(len(self._bits), len(o._bits))
        return Flags([op(self(i), o(i)) for i in range(n)], rest=op(self._rest, o._rest))

    def __and__(self, other: Any) -> Flags:
        return self._combine(other, lambda a, b: a and b)

    def __or__(self, other: Any) -> Flags:
        return self._combine(other, lambda a, b: a or b)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Flags):
            return NotImplemented
        n = max(len(self._bits), len(other._bits))
        return self._rest == other._rest and all(self(i) == other(i) for i in range(n))

    def __hash__(self) -> int:
        bits = list(self._bits)
        while bits and bits[-1] == self._rest:
            bits.pop()
        return hash((tuple(bits), self._rest))

    def __str__(self) -> str:
        text = "".join("1" if b else "0" for b in self._bits)
        if self._rest:  # "000000[1...]": six zeros, then ones
            return text + "[1...]" if text else "all"
        return text or "none"

    def __repr__(self) -> str:
        if not self._bits:
            return f"Flags({self._rest})"
        text = "".join("1" if b else "0" for b in self._bits)
        return f"Flags({text!r}, rest=True)" if self._rest else f"Flags({text!r})"


def _as_flags(v: Any) -> Flags:
    return v if isinstance(v, Flags) else Flags(v)


#: Signal type of ``selec`` / ``controlSelec`` (SoT's ``flag``): a :class:`Flags`;
#: constants may be written as strings (``"111000"``), bools or boolean sequences.
FLAGS = SignalType(
    "flag", _as_flags, lambda f: np.array([float(b) for b in f._bits] or [float(f.rest)])
)


def _take(x: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
    return x if rows is None else x[rows]


# -- base class -----------------------------------------------------------------------
class FeatureAbstract(Entity):
    """Common part of every feature: ``selec`` in; ``error``, ``jacobian``,
    ``errordot``, ``dim`` out; the reference commands.

    Subclasses give the signals each output reads (``_errorDeps``, ``_jacobianDeps``,
    ``_errordotDeps``) and the computations (``_error``, ``_jacobian``, ``_errordot``),
    which receive the values of those signals and return the selected rows.
    ``_wire()`` sets the dependencies; it runs at construction and whenever the
    reference changes.

    Reference. Some features (``FeatureGeneric``, ``FeatureVisualPoint``) take their
    desired value from a second feature of the same class, SoT's ``featureDes``:
    ``feature.setReference(featureDes)`` (or its name). The others have reference
    signals (``FeaturePose.reference``, ``FeaturePosture.posture``).
    """

    className = "FeatureAbstract"

    selec = Input(
        FLAGS,
        default=Flags(True),
        doc="selected rows (SoT flags, left to right: character i selects row i); all",
    )

    @Output(VECTOR, timeDependent=False)
    def error(self, *values: Any) -> np.ndarray:
        """e: the selected rows of the error (units of the feature)."""
        return self._error(*values)

    @Output(MATRIX, timeDependent=False)
    def jacobian(self, *values: Any) -> np.ndarray:
        """J = de/dq, dim x nv: de/dt = J v + errordot."""
        return self._jacobian(*values)

    @Output(VECTOR, timeDependent=False)
    def errordot(self, *values: Any) -> np.ndarray:
        """de/dt at a fixed configuration (a moving reference), selected rows."""
        return self._errordot(*values)

    @Output(INT, deps=("error",))
    def dim(self, error: np.ndarray) -> int:
        """Number of selected rows."""
        return int(error.shape[0])

    #: whether ``setReference`` accepts a feature of the same class
    _acceptsReferenceFeature = False

    def __init__(self, name: str) -> None:
        if type(self) is FeatureAbstract:
            raise EntityError(
                f"FeatureAbstract({name}): FeatureAbstract is abstract; create a "
                "FeaturePose, FeatureGeneric, FeaturePosture, ... instead"
            )
        self._reference: FeatureAbstract | None = None
        self._indexCache: tuple[Any, int, Any] = (None, -1, None)
        # the subclass's computations are the callbacks (no dispatch at each tick)
        self.error.setFunction(self._error)
        self.jacobian.setFunction(self._jacobian)
        self.errordot.setFunction(self._errordot)
        self._wire()

    # -- wiring -----------------------------------------------------------------------
    def _errorDeps(self) -> list[Signal]:
        raise NotImplementedError

    def _jacobianDeps(self) -> list[Signal]:
        raise NotImplementedError

    def _errordotDeps(self) -> list[Signal]:
        """Default: no moving reference, errordot is zero (it reads ``error`` for its
        size)."""
        return [self.error]

    def _errordot(self, error: np.ndarray, *_: Any) -> np.ndarray:
        return np.zeros(error.shape[0])

    def _error(self, *values: Any) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _jacobian(self, *values: Any) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _wire(self) -> None:
        """Set the outputs' dependencies from the current inputs and reference."""
        self.error.setDependencies(self._errorDeps())
        self.jacobian.setDependencies(self._jacobianDeps())
        self.errordot.setDependencies(self._errordotDeps())

    def _rows(self, selec: Flags, n: int) -> np.ndarray | None:
        """Row indices selected by ``selec`` among ``n``; an error naming ``selec``."""
        rows = selec._cache.get(n, _MISSING)  # the tick's path: one lookup
        if rows is _MISSING:
            try:
                rows = selec.rows(n)
            except ValueError as exc:
                raise SignalTypeError(f"{self.selec.name}: {exc}") from None
        return rows

    def _index(self, selec: Flags, n: int) -> np.ndarray:
        """The rows selected by ``selec`` among ``n`` as an int64 array (all of them
        when ``selec`` selects all), cached for the last ``(selec, n)``: what the row
        kernels take."""
        c = self._indexCache
        if c[0] is selec and c[1] == n:
            return c[2]
        rows = self._rows(selec, n)
        idx = np.arange(n, dtype=np.int64) if rows is None else np.array(rows, dtype=np.int64)
        self._indexCache = (selec, n, idx)
        return idx

    def _rowOp(self) -> RowOp | None:
        """How an SOT writes this feature's rows straight into its buffer (see
        :mod:`sotpy.tasks.rows`); None if it must read the feature's signals. This one
        calls the ``error`` and ``jacobian`` callbacks; the common features override
        it with an operation of the compiled kernel."""
        return callbackOp(self.error, self.jacobian)

    def _ownCallbacks(self, cls: type[FeatureAbstract]) -> bool:
        """Whether this feature is exactly a ``cls`` whose ``error`` and ``jacobian``
        compute with ``cls``'s methods at every tick (a row kernel may replace them)."""
        return (
            type(self) is cls
            and _rowkernels.write_rows is not None
            and computedByOwnCallback(self.error, cls._error)
            and computedByOwnCallback(self.jacobian, cls._jacobian)
        )

    def _sizeError(self, sig: Signal, value: Any, expected: str) -> SignalTypeError:
        shape = getattr(value, "shape", None)
        got = f"shape {shape}" if shape is not None else f"a {type(value).__name__}"
        return SignalTypeError(f"{sig.name}: expected {expected}, received {got}")

    # -- reference --------------------------------------------------------------------
    @command
    def setReference(self, feature: FeatureAbstract | str) -> None:
        """Take the desired value from ``feature`` (an entity or its name), a feature
        of the same class (SoT's ``featureDes``): ``e = s - s*`` with ``s*`` read from
        its inputs."""
        if not self._acceptsReferenceFeature:
            raise CommandError(
                f"{self.className}({self.name}).setReference: a {self.className} takes its "
                f"reference from signals ({self._referenceHint()}), not from a second feature"
            )
        ref = feature
        if isinstance(feature, str):
            try:
                ref = pool.getEntity(feature)
            except EntityError as exc:
                raise CommandError(f"{self.className}({self.name}).setReference: {exc}") from None
        if type(ref) is not type(self):
            raise CommandError(
                f"{self.className}({self.name}).setReference: the reference must be a "
                f"{self.className}, got {ref!r}"
            )
        if ref is self:
            raise CommandError(
                f"{self.className}({self.name}).setReference: a feature cannot be its own reference"
            )
        old = self._reference
        self._reference = ref  # type: ignore[assignment]
        try:
            self._wire()
        except BaseException:
            self._reference = old
            self._wire()
            raise

    @command
    def unsetReference(self) -> None:
        """Forget the reference feature (``s* = 0``, or the reference signals)."""
        if self._reference is not None:
            self._reference = None
            self._wire()

    @command
    def getReference(self) -> str:
        """Name of the reference feature, or ``"none"`` (SoT's)."""
        return self._reference.name if self._reference is not None else "none"

    def _referenceHint(self) -> str:
        return "see its doc"


# -- FeatureGeneric -------------------------------------------------------------------
class FeatureGeneric(FeatureAbstract):
    """A feature given by its value and Jacobian: ``e = errorIN - ref.errorIN``.

    ``errorIN`` (size m) is the value ``s`` (a CoM position, ...), ``jacobianIN``
    (m x nv) its Jacobian, ``errordotIN`` (optional, size m or empty) its rate of change
    at a fixed configuration ``ds/dt|_q``. With a reference feature
    (``setReference(featureDes)``, another ``FeatureGeneric`` whose ``errorIN`` holds
    ``s*`` and whose ``errordotIN`` holds ``ds*/dt``):

    - ``error = errorIN - featureDes.errorIN``;
    - ``jacobian = jacobianIN``;
    - ``errordot = errordotIN - featureDes.errordotIN`` (an empty vector counts as zero).

    Without a reference, ``error = errorIN`` and ``errordot = errordotIN``.

    Note: the SoT's ``FeatureGeneric`` copied ``featureDes.errordotIN`` into
    ``errordot`` without the minus sign; here ``errordotIN`` is always the rate of the
    value it sits next to, so the desired velocity goes into
    ``featureDes.errordotIN`` as it is.
    """

    className = "FeatureGeneric"

    errorIN = Input(VECTOR, doc="s: the feature's value (size m)")
    jacobianIN = Input(MATRIX, doc="ds/dq (m x nv)")
    errordotIN = Input(VECTOR, default=_EMPTY, doc="ds/dt at fixed q (size m; empty: zero)")

    _acceptsReferenceFeature = True

    def _errorDeps(self) -> list[Signal]:
        deps = [self.selec, self.errorIN]
        if self._reference is not None:
            deps.append(self._reference.errorIN)  # type: ignore[attr-defined]
        return deps

    def _jacobianDeps(self) -> list[Signal]:
        return [self.selec, self.jacobianIN]

    def _errordotDeps(self) -> list[Signal]:
        deps = [self.selec, self.errorIN, self.errordotIN]
        if self._reference is not None:
            deps.append(self._reference.errordotIN)  # type: ignore[attr-defined]
        return deps

    def _error(self, selec: Flags, s: np.ndarray, sdes: np.ndarray | None = None) -> np.ndarray:
        if sdes is not None:
            if sdes.shape != s.shape:
                raise self._sizeError(
                    self._reference.errorIN,  # type: ignore[union-attr]
                    sdes,
                    f"a vector of the size of {self.errorIN.name} ({s.shape[0]})",
                )
            s = s - sdes
        return _take(s, self._rows(selec, s.shape[0]))

    def _jacobian(self, selec: Flags, J: np.ndarray) -> np.ndarray:
        return _take(J, self._rows(selec, J.shape[0]))

    def _rowOp(self) -> RowOp | None:
        if not self._ownCallbacks(FeatureGeneric):
            return super()._rowOp()
        error, jacobian = self.error, self.jacobian
        ne = len(error._srcs)  # (selec, errorIN[, reference's errorIN])
        ndarray = np.ndarray

        def bind(at: tuple[int, ...]) -> Gather:
            aSel, aJ, aS = at[:3]
            aRef = at[3] if ne == 3 else -1

            def gather(v: Any, o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
                selec, s, J = v[o], v[o + 1], v[o + ne + 1]
                if type(s) is not ndarray or type(J) is not ndarray or s.ndim != 1 or J.ndim != 2:
                    return False  # the callbacks say what is wrong
                if ne == 3:
                    sdes = v[o + 2]
                    if type(sdes) is not ndarray or sdes.ndim != 1:
                        return False
                    args[aRef] = sdes
                args[aSel] = self._index(selec, s.shape[0])
                args[aJ], args[aS] = J, s
                return True

            return gather

        spec = "imvv" if ne == 3 else "imv"  # (selection, J, s[, s*])
        return RowOp(_rowkernels.GENERIC, spec, (*error._srcs, *jacobian._srcs), bind)

    def _errordot(
        self, selec: Flags, s: np.ndarray, sdot: np.ndarray, sdesdot: np.ndarray | None = None
    ) -> np.ndarray:
        m = s.shape[0]
        out = np.zeros(m)
        for sig, v, sign in (
            (self.errordotIN, sdot, 1.0),
            (getattr(self._reference, "errordotIN", None), sdesdot, -1.0),
        ):
            if v is None or v.shape[0] == 0:
                continue
            if v.shape != (m,):
                raise self._sizeError(sig, v, f"a vector of size {m} (or empty for zero)")  # type: ignore[arg-type]
            out += sign * v
        return _take(out, self._rows(selec, m))


# -- FeaturePose ----------------------------------------------------------------------
def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


class FeaturePose(FeatureAbstract):
    """An SE(3) frame task, error as in the SoT slides: translation and u-theta.

    Inputs: ``position`` (SE3, ``M = oMf``, plugged from ``dynamic.<op>``), ``Jq``
    (6 x nv LOCAL Jacobian of the frame, from ``dynamic.J<op>``), ``reference`` (SE3,
    ``M* = oMf*``, the desired placement) and ``referenceVelocity`` (6, default 0:
    ``nu* = (v*, w*)``, the spatial velocity of the desired frame expressed in the
    desired frame, linear first, m/s and rad/s: ``dM*/dt = M* [nu*]``).

    With ``Mr = M*^-1 M = (Rr, p)`` (the frame seen from the desired frame):

    - ``error = (p, log3(Rr))`` (m, rad): the position of the frame in the desired
      frame, then the rotation vector (u-theta) of ``R*^T R``;
    - ``jacobian = diag(Rr, Jlog3(Rr)) Jq`` (exact: ``de/dt = J v`` for a fixed
      reference);
    - ``errordot = (-w* x p - v*, -Jlog3(Rr) Rr^T w*)`` (zero when ``nu* = 0``).

    Rows 0-2 (``"111000"``) are a pure position task (the frame's origin goes to the
    desired origin, expressed in the desired frame's axes), rows 3-5 a pure
    orientation task. ``keep()`` sets the reference to the current placement.
    (sot-core's ``FeaturePose`` expresses the translation rows in the world axes.)

    ``frame("desired")`` (the default) is the error above, the one of SoT's
    ``FeaturePoint6d`` in its ``"desired"`` frame. ``frame("current")`` is SoT's other
    choice: the error of the desired frame seen from the current one, with
    ``Mc = M^-1 M* = (Rc, X)``:

    - ``error = (X, log3(Rc))``: ``X = R^T (p* - p)``, the desired origin in the
      current frame, then the rotation vector of ``R^T R*``;
    - ``jacobian = (-Jv + [X]x Jw, -Jlog3(Rc) Rc^T Jw)`` with ``Jq = (Jv, Jw)`` (exact;
      SoT's wrote ``-Rc^T Jw`` for the rotation rows, its value at zero error);
    - ``errordot = (Rc v*, Jlog3(Rc) w*)``.

    Both go to zero at the same placement; they differ in the axes of the error, so
    in the path (and in which rows a selection like ``"111000"`` keeps). ``getFrame()``
    says which one is used.
    """

    className = "FeaturePose"

    position = Input(SE3, doc="M = oMf: placement of the frame in the world (m)")
    Jq = Input(MATRIX, doc="6 x nv LOCAL Jacobian of the frame, linear rows first")
    reference = Input(SE3, doc="M* = oMf*: desired placement of the frame (m)")
    referenceVelocity = Input(
        VECTOR,
        default=np.zeros(6),
        doc="nu* = (v*, w*): velocity of the desired frame in itself (m/s, rad/s)",
    )

    def _referenceHint(self) -> str:
        return "its input 'reference', or keep()"

    def _errorDeps(self) -> list[Signal]:
        return [self.selec, self.position, self.reference]

    def _jacobianDeps(self) -> list[Signal]:
        return [self.selec, self.position, self.reference, self.Jq]

    def _errordotDeps(self) -> list[Signal]:
        return [self.selec, self.position, self.reference, self.referenceVelocity]

    # the two variants differ only in these three functions of Mr
    #: whether the three functions below use the rotation matrix of Mr
    _usesRotation = True

    def __init__(self, name: str) -> None:
        self._D = np.zeros((6, 6))  # buffer of _poseJacobian (off-diagonal blocks: 0)
        self._rel: list[Any] = [None, None, None, None]  # (M, M*, Mr, R) of the last tick
        self._splitCache: tuple[Any, ...] = (_MISSING, None, None)
        self._current = False  # frame("current"): SoT's error of M* seen from M
        super().__init__(name)

    @command
    def frame(self, frame: str) -> None:
        """Set computation frame: 'desired' (default) or 'current'

        'desired': error = (t, log3) of M*^-1 M, the frame seen from the desired one;
        'current': error = (t, log3) of M^-1 M*, the desired frame seen from the current
        one (SoT's FeaturePoint6d choices; see the class doc).
        """
        if frame not in ("current", "desired"):
            raise CommandError(
                f"{self.className}({self.name}).frame: expected 'current' or 'desired', got "
                f"{frame!r}; the frame is left {self.getFrame()!r}"
            )
        if frame == "current" and not self._usesRotation:
            raise CommandError(
                f"{self.className}({self.name}).frame: a {self.className} has one error, "
                "log6(M*^-1 M) ('desired'); SoT's 'current' frame is FeaturePose's "
                "frame('current')"
            )
        current = frame == "current"
        if current != self._current:
            self._current = current
            self._wire()  # the outputs are recomputed, compiled plans recompiled

    @command
    def getFrame(self) -> str:
        """Get frame of computation of the error: 'desired' or 'current'."""
        return "current" if self._current else "desired"

    def _relative(self, M: pin.SE3, Mdes: pin.SE3) -> tuple[pin.SE3, np.ndarray | None]:
        """(Mr = M*^-1 M, its rotation), computed once for the error and the Jacobian of
        a tick (placements are fresh objects when they change)."""
        c = self._rel
        if c[0] is M and c[1] is Mdes:
            return c[2], c[3]
        rel = Mdes.actInv(M)
        R = rel.rotation if self._usesRotation else None
        c[:] = M, Mdes, rel, R  # in place: no entity attribute set per tick
        return rel, R

    # the two variants differ only in these three functions of Mr (and R = its rotation)
    def _poseError(self, rel: pin.SE3, R: np.ndarray, rows: np.ndarray | None) -> np.ndarray:
        """The selected rows of the error."""
        t, r = self._split(rows)
        if t is None and r is _NONE:  # "111000": the position alone, no log3
            return rel.translation.copy()  # (a view into rel otherwise)
        e = np.concatenate((rel.translation, pin.log3(R)))
        return e if rows is None else e[rows]

    def _poseJacobian(
        self, rel: pin.SE3, R: np.ndarray, rows: np.ndarray | None, Jq: np.ndarray
    ) -> np.ndarray:
        """The selected rows of ``D Jq``, ``D = diag(R, Jlog3(R))``; a position-only or
        rotation-only selection uses its block alone (one small product costs about as
        much as a big one here, so the full selection is one ``6 x 6`` product)."""
        t, r = self._split(rows)
        if r is _NONE:
            return R @ Jq[:3] if t is None else R[t] @ Jq[:3]
        if t is _NONE:
            Jl = pin.Jlog3(R)
            return Jl @ Jq[3:] if r is None else Jl[r] @ Jq[3:]
        D = self._D
        D[:3, :3] = R
        D[3:, 3:] = pin.Jlog3(R)
        return D @ Jq if rows is None else D[rows] @ Jq

    def _split(self, rows: np.ndarray | None) -> tuple[Any, Any]:
        """The selected rows by block, (translation, rotation): ``None`` for the whole
        block, ``_NONE`` for none of it, else the indices within the block."""
        c = self._splitCache
        if c[0] is rows:
            return c[1], c[2]
        if rows is None:
            t = r = None
        else:
            t, r = rows[rows < 3], rows[rows >= 3] - 3
            t = None if len(t) == 3 else (_NONE if len(t) == 0 else t)
            r = None if len(r) == 3 else (_NONE if len(r) == 0 else r)
        self._splitCache = (rows, t, r)
        return t, r

    def _poseErrordot(self, rel: pin.SE3, R: np.ndarray, nu: np.ndarray) -> np.ndarray:
        v, w = nu[:3], nu[3:]
        p = rel.translation
        out = np.empty(6)
        # -(w x p) - v, written out (numpy's cross costs 15 us on 3-vectors)
        out[0] = -(w[1] * p[2] - w[2] * p[1]) - v[0]
        out[1] = -(w[2] * p[0] - w[0] * p[2]) - v[1]
        out[2] = -(w[0] * p[1] - w[1] * p[0]) - v[2]
        out[3:] = -pin.Jlog3(R) @ (R.T @ w)
        return out

    def _error(self, selec: Flags, M: pin.SE3, Mdes: pin.SE3) -> np.ndarray:
        if self._current:
            Mc = M.actInv(Mdes)
            e = np.concatenate((Mc.translation, pin.log3(Mc.rotation)))
            return _take(e, self._rows(selec, 6))
        rel, R = self._relative(M, Mdes)
        return self._poseError(rel, R, self._rows(selec, 6))

    def _jacobian(self, selec: Flags, M: pin.SE3, Mdes: pin.SE3, Jq: np.ndarray) -> np.ndarray:
        rows = self._rows(selec, 6)
        if Jq.shape[0] != 6:
            raise self._sizeError(self.Jq, Jq, "a 6 x nv Jacobian (LOCAL, linear rows first)")
        if self._current:
            Mc = M.actInv(Mdes)
            Rc = Mc.rotation
            L = np.zeros((6, 6))
            L[:3, :3] = -np.eye(3)
            L[:3, 3:] = _skew(Mc.translation)
            L[3:, 3:] = -pin.Jlog3(Rc) @ Rc.T
            return _take(L, rows) @ Jq
        rel, R = self._relative(M, Mdes)
        return self._poseJacobian(rel, R, rows, Jq)

    def _rowOp(self) -> RowOp | None:
        if self._current or not self._ownCallbacks(FeaturePose):
            return super()._rowOp()  # frame("current"), FeaturePoseSE3: the callbacks
        se3, ndarray = pin.SE3, np.ndarray

        def bind(at: tuple[int, ...]) -> Gather:
            aSel, aH, aHd, aJ = at
            ref: list[Any] = [None, None]  # the reference and its matrix, by identity

            def gather(v: Any, o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
                selec, M, Mdes, Jq = v[o], v[o + 1], v[o + 2], v[o + 3]
                if type(M) is not se3 or type(Mdes) is not se3 or type(Jq) is not ndarray:
                    return False
                if Jq.ndim != 2:
                    return False
                if ref[0] is not Mdes:
                    ref[0], ref[1] = Mdes, Mdes.homogeneous
                sel = self._index(selec, 6)
                args[aSel], args[aH], args[aHd], args[aJ] = sel, M.homogeneous, ref[1], Jq
                return True

            return gather

        # the sources the jacobian callback reads (selec, position, reference, Jq)
        return RowOp(_rowkernels.POSE, "immm", self.jacobian._srcs, bind)

    def _errordot(self, selec: Flags, M: pin.SE3, Mdes: pin.SE3, nu: np.ndarray) -> np.ndarray:
        rows = self._rows(selec, 6)
        if nu.shape != (6,):
            raise self._sizeError(self.referenceVelocity, nu, "a vector of size 6")
        if not nu.any():
            return np.zeros(6 if rows is None else len(rows))
        if self._current:
            Rc = M.actInv(Mdes).rotation
            out = np.concatenate((Rc @ nu[:3], pin.Jlog3(Rc) @ nu[3:]))
            return _take(out, rows)
        return _take(self._poseErrordot(*self._relative(M, Mdes), nu), rows)

    @command
    def keep(self) -> None:
        """Set ``reference`` to the current ``position`` (the error becomes zero) and
        ``referenceVelocity`` to zero."""
        self.reference.value = self.position.value
        self.referenceVelocity.value = np.zeros(6)


class FeaturePoseSE3(FeaturePose):
    """An SE(3) frame task with the error ``e = log6(M*^-1 M)`` (SoT's
    ``FeaturePoseSE3``).

    Same inputs as :class:`FeaturePose`. With ``Mr = M*^-1 M``:

    - ``error = log6(Mr)`` (linear then angular part of the twist that moves the
      desired frame onto the frame in unit time, expressed in the desired frame);
    - ``jacobian = Jlog6(Mr) Jq``;
    - ``errordot = -Jlog6(Mr) Ad(Mr^-1) nu*``.

    Its linear rows are not the position error when the orientation differs (they mix
    in the rotation: ``log6`` follows a screw motion); select rows with
    :class:`FeaturePose` for a position-only task.
    """

    className = "FeaturePoseSE3"

    _usesRotation = False

    def _poseError(self, rel: pin.SE3, R: None, rows: np.ndarray | None) -> np.ndarray:
        return _take(pin.log6(rel).vector, rows)

    def _poseJacobian(
        self, rel: pin.SE3, R: None, rows: np.ndarray | None, Jq: np.ndarray
    ) -> np.ndarray:
        return _take(pin.Jlog6(rel), rows) @ Jq

    def _poseErrordot(self, rel: pin.SE3, R: None, nu: np.ndarray) -> np.ndarray:
        return -pin.Jlog6(rel) @ rel.actInv(pin.Motion(nu)).vector


class FeaturePoint6d(FeaturePose):
    """SoT's ``FeaturePoint6d``: a :class:`FeaturePose` whose reference may be a second
    feature of the same class, as SoT scripts build it.

    ``setReference(featureDes)`` (an entity or its name) makes ``reference`` follow
    ``featureDes.position`` (``plug(featureDes.position, reference)``): writing the
    desired placement in ``featureDes.position`` moves the target, and ``keep()``
    writes the current placement there. Without a reference feature it is a
    :class:`FeaturePose` (``reference`` is the desired placement). Errors, Jacobians,
    ``frame('current'|'desired')``: those of :class:`FeaturePose`.
    """

    className = "FeaturePoint6d"

    _acceptsReferenceFeature = True

    def _wire(self) -> None:
        ref = self._reference
        if ref is not None and self.reference.source is not ref.position:  # type: ignore[attr-defined]
            plug(ref.position, self.reference)  # type: ignore[attr-defined]
        elif ref is None and isinstance(self.reference.source, InputSignal):
            self.reference.unplug()
        super()._wire()

    @command
    def keep(self) -> None:
        """Make the current placement the desired one: written in the reference
        feature's ``position`` when there is one (SoT's), else in ``reference``; the
        reference velocity becomes zero."""
        M = self.position.value
        if self._reference is not None:
            self._reference.position.value = M  # type: ignore[attr-defined]
        else:
            self.reference.value = M
        self.referenceVelocity.value = np.zeros(6)


# -- model-based features -------------------------------------------------------------
def _checkModel(cls: str, name: str, model: Any) -> pin.Model:
    if not isinstance(model, pin.Model):
        raise EntityError(
            f"{cls}({name}): the second argument must be a pinocchio.Model (e.g. "
            f"dynamic.model), got {type(model).__name__}"
        )
    return model.copy()


def _jointOfDof(model: pin.Model) -> list[int]:
    """Index of the joint of each velocity DoF."""
    owner = [0] * model.nv
    for j in range(1, model.njoints):
        for k in range(model.idx_vs[j], model.idx_vs[j] + model.nvs[j]):
            owner[k] = j
    return owner


class FeaturePosture(FeatureAbstract):
    """Joint posture: ``e = difference(q*, q)``, the tangent vector such that
    ``q = q* (+) e`` (``pinocchio.difference``), restricted to selected DoFs.

    ``FeaturePosture(name, model)`` (``model``: a ``pinocchio.Model``, e.g.
    ``dynamic.model``). Inputs: ``state`` (``q``, size nq, plugged from the device),
    ``posture`` (``q*``, size nq), ``postureDot`` (``v*``, size nv, default 0: the
    velocity of the desired posture, ``q*(t + dt) = q*(t) (+) v* dt``).

    Rows are velocity DoFs (``0..nv-1``, a free flyer's six first). ``selec`` selects
    them; by default every DoF except those of a free-flyer root joint.
    ``selectDof(i, True/False)`` changes one.

    - ``error`` (rad, m): ``difference(q*, q)[rows]`` (for a revolute joint, ``q - q*``);
    - ``jacobian``: the selected rows of ``d difference(q*, q) / dq`` (ARG1), which is
      the identity for one-DoF joints: rows of the identity matrix; for a free flyer or
      a spherical joint, Pinocchio's ``dDifference`` block;
    - ``errordot = (d difference / dq*) v*`` (ARG0): ``-v*`` for one-DoF joints.
    """

    className = "FeaturePosture"

    state = Input(VECTOR, doc="q: Pinocchio configuration of the robot (size nq)")
    posture = Input(VECTOR, doc="q*: desired configuration (size nq)")
    postureDot = Input(VECTOR, doc="v*: velocity of the desired posture (size nv), 0")

    def __init__(self, name: str, model: pin.Model) -> None:
        self.model = _checkModel(self.className, name, model)
        model = self.model
        self._owner = _jointOfDof(model)
        #: DoFs whose Jacobian row is a row of the identity (joints with one DoF)
        self._simple = np.array([model.nvs[j] == 1 for j in self._owner], dtype=bool)
        self._hasUnitNorm = any(model.nqs[j] != model.nvs[j] for j in range(1, model.njoints))
        self._ffDofs = 0
        if model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer":
            self._ffDofs = 6
        self._jcache: tuple[Flags, np.ndarray] | None = None
        self._postureCache: tuple[Flags, Any] | None = None
        self._checked: np.ndarray | None = None  # the posture array last checked
        self.postureDot.setDefault(np.zeros(model.nv))
        default = Flags([False] * self._ffDofs, rest=True)
        self.selec.setDefault(default)
        self.selec.value = default
        super().__init__(name)

    def _referenceHint(self) -> str:
        return "its input 'posture'"

    def _errorDeps(self) -> list[Signal]:
        return [self.selec, self.state, self.posture]

    def _jacobianDeps(self) -> list[Signal]:
        return [self.selec, self.state, self.posture]

    def _errordotDeps(self) -> list[Signal]:
        return [self.selec, self.state, self.posture, self.postureDot]

    def _check(self, sig: Signal, q: np.ndarray) -> None:
        if q is self._checked:  # the same array as at the last check (a constant)
            return
        model = self.model
        if q.shape != (model.nq,):
            raise self._sizeError(sig, q, f"a configuration of size nq = {model.nq}")
        if self._hasUnitNorm and not pin.isNormalized(model, q, 1e-6):
            raise SignalTypeError(
                f"{sig.name}: the configuration is not normalised (a quaternion or a "
                "(cos, sin) pair has a norm differing from 1 by more than 1e-06)"
            )
        if sig is self.posture:
            self._checked = q

    def _error(self, selec: Flags, q: np.ndarray, qdes: np.ndarray) -> np.ndarray:
        self._check(self.state, q)
        self._check(self.posture, qdes)
        e = pin.difference(self.model, qdes, q)
        return _take(e, self._rows(selec, self.model.nv))

    def _jacobian(self, selec: Flags, q: np.ndarray, qdes: np.ndarray) -> np.ndarray:
        cached = self._jcache  # only ever set for one-DoF joints (constant rows)
        if cached is not None and cached[0] is selec:
            return cached[1]
        nv = self.model.nv
        rows = self._rows(selec, nv)
        idx = np.arange(nv) if rows is None else rows
        if self._simple[idx].all():
            J = np.zeros((len(idx), nv))
            J[np.arange(len(idx)), idx] = 1.0
            J.flags.writeable = False
            self._jcache = (selec, J)
            return J
        self._check(self.state, q)
        self._check(self.posture, qdes)
        D = pin.dDifference(self.model, qdes, q, pin.ArgumentPosition.ARG1)
        return D[idx]

    def _postureIndex(self, selec: Flags) -> tuple[np.ndarray, np.ndarray] | None:
        """``(iq, iv)`` of the selected DoFs when each belongs to a joint whose
        configuration is its coordinate (``nq = nv = 1``: ``difference(q*, q) = q -
        q*``, Jacobian row the identity's); None otherwise. Cached for ``selec``."""
        c = self._postureCache
        if c is not None and c[0] is selec:
            return c[1]
        model = self.model
        idx = self._index(selec, model.nv)
        plan = None
        if all(model.nqs[self._owner[i]] == 1 == model.nvs[self._owner[i]] for i in idx):
            iq = np.array([model.idx_qs[self._owner[i]] for i in idx], dtype=np.int64)
            plan = (iq, idx)
        self._postureCache = (selec, plan)
        return plan

    def _rowOp(self) -> RowOp | None:
        if not self._ownCallbacks(FeaturePosture):
            return super()._rowOp()
        generic = super()._rowOp()  # joints with a richer configuration: the callbacks
        if generic is None:
            return None
        ndarray, model, isNormalized = np.ndarray, self.model, pin.isNormalized
        nv, shape, unit = model.nv, (model.nq,), self._hasUnitNorm

        def bind(at: tuple[int, ...]) -> Gather:
            aiq, aiv, aq, aqd, aJ, ae = at
            callbacks = generic.bind((aJ, ae))

            def gather(v: Any, o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
                selec, q, qdes = v[o], v[o + 1], v[o + 2]
                plan = self._postureIndex(selec)
                if plan is None or n != nv:
                    args[aiv] = CALLBACK_ROWS  # the kernel copies the callbacks' rows
                    return callbacks(v, o, args, scal, n)
                if type(q) is not ndarray or type(qdes) is not ndarray:
                    return False
                # the callbacks' checks, the same errors (the posture: once per array)
                if q.shape != shape or (unit and not isNormalized(model, q, 1e-6)):
                    self._check(self.state, q)
                if qdes is not self._checked:
                    self._check(self.posture, qdes)
                args[aiq], args[aiv] = plan
                args[aq], args[aqd] = q, qdes
                return True

            return gather

        # (iq, iv, q, q*) for the kernel's formula, or (J, e) from the callbacks
        return RowOp(_rowkernels.POSTURE, "iivvmv", generic.sources, bind)

    def _errordot(
        self, selec: Flags, q: np.ndarray, qdes: np.ndarray, vdes: np.ndarray
    ) -> np.ndarray:
        nv = self.model.nv
        rows = self._rows(selec, nv)
        if vdes.shape != (nv,):
            raise self._sizeError(self.postureDot, vdes, f"a vector of size nv = {nv}")
        if not vdes.any():
            return np.zeros(nv if rows is None else len(rows))
        self._check(self.state, q)
        self._check(self.posture, qdes)
        D = pin.dDifference(self.model, qdes, q, pin.ArgumentPosition.ARG0)
        return _take(D @ vdes, rows)

    @command
    def selectDof(self, dofId: int, control: bool) -> None:
        """Select (``True``) or release (``False``) velocity DoF ``dofId`` (0..nv-1; a
        free flyer's are 0-5). Sets ``selec`` to a constant."""
        nv = self.model.nv
        if not 0 <= dofId < nv:
            raise CommandError(
                f"{self.className}({self.name}).selectDof: argument 'dofId': expected a "
                f"velocity index in 0..{nv - 1}, got {dofId}"
            )
        self.selec.value = self.selec.value.set(dofId, control)

    @command
    def dofNames(self) -> list[str]:
        """Name of each velocity DoF (``joint`` or ``joint[k]`` for multi-DoF joints)."""
        names = []
        for k, j in enumerate(self._owner):
            nvj = self.model.nvs[j]
            n = self.model.names[j]
            names.append(n if nvj == 1 else f"{n}[{k - self.model.idx_vs[j]}]")
        return names


class FeatureJointLimits(FeatureAbstract):
    """Joint ranges normalised to ``[-1, 1]`` (SoT's ``FeatureJointLimits``).

    ``FeatureJointLimits(name, model)``. Inputs: ``joint`` (``q``, size nq),
    ``upperJl``/``lowerJl`` (``u``, ``l``, size nq; default: the model's limits, or plug
    ``dynamic.upperJl``/``lowerJl``). Output ``widthJl = u - l`` (size nq).

    Rows are velocity DoFs (``0..nv-1``) of one-DoF joints (revolute, prismatic) with
    finite limits; ``selec`` defaults to all of them, and selecting another DoF (a free
    flyer's, an unbounded joint's) is an error. For DoF ``i`` with coordinate ``q_i``:

    - ``error_i = 2 (q_i - l_i) / w_i - 1`` with ``w_i = u_i - l_i``: ``-1`` at the
      lower limit, ``0`` at mid-range, ``1`` at the upper limit (no unit);
    - ``jacobian``: ``2 / w_i`` at column ``i`` (the SoT wrote ``1 / w_i``, which is
      not the derivative of its error);
    - ``activation_i`` (output): ``0`` while ``|error_i| < threshold``, then
      ``(|error_i| - threshold) / (1 - threshold)``, capped at 1 (``setThreshold``,
      default 0.9): how close to a limit each joint is, e.g. to weight an avoidance
      task. Hard joint limits belong to the solver (or a ``TaskInequality``).
    """

    className = "FeatureJointLimits"

    joint = Input(VECTOR, doc="q: Pinocchio configuration (size nq)")
    upperJl = Input(VECTOR, doc="u: upper position limits (size nq)")
    lowerJl = Input(VECTOR, doc="l: lower position limits (size nq)")

    @Output(VECTOR, deps=("upperJl", "lowerJl"))
    def widthJl(self, u: np.ndarray, l: np.ndarray) -> np.ndarray:  # noqa: E741
        """w = u - l: width of each joint range (size nq)."""
        return u - l

    @Output(VECTOR, deps=("error",))
    def activation(self, e: np.ndarray) -> np.ndarray:
        """Closeness to a limit, in [0, 1], per selected row (see the class doc)."""
        th = self._threshold
        return np.clip((np.abs(e) - th) / (1.0 - th), 0.0, 1.0)

    def __init__(self, name: str, model: pin.Model) -> None:
        self.model = _checkModel(self.className, name, model)
        model = self.model
        self._threshold = 0.9
        qidx = np.full(model.nv, -1)
        for j in range(1, model.njoints):
            if model.nqs[j] == 1 and model.nvs[j] == 1:
                qidx[model.idx_vs[j]] = model.idx_qs[j]
        self._qidx = qidx
        lo, up = model.lowerPositionLimit, model.upperPositionLimit
        limited = [
            bool(k >= 0 and abs(lo[k]) < 1e300 and abs(up[k]) < 1e300 and up[k] > lo[k])
            for k in qidx
        ]
        self.upperJl.setDefault(np.array(up))
        self.lowerJl.setDefault(np.array(lo))
        default = Flags(limited)
        self.selec.setDefault(default)
        self.selec.value = default
        super().__init__(name)

    def _referenceHint(self) -> str:
        return "its inputs 'upperJl' and 'lowerJl'"

    def _errorDeps(self) -> list[Signal]:
        return [self.selec, self.joint, self.upperJl, self.lowerJl]

    def _jacobianDeps(self) -> list[Signal]:
        return [self.selec, self.upperJl, self.lowerJl]

    def _limits(
        self,
        selec: Flags,
        u: np.ndarray,
        l: np.ndarray,  # noqa: E741
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(DoF rows, their q indices, l, w) for the selected DoFs, checked."""
        nq, nv = self.model.nq, self.model.nv
        for sig, v in ((self.upperJl, u), (self.lowerJl, l)):
            if v.shape != (nq,):
                raise self._sizeError(sig, v, f"a vector of size nq = {nq}")
        rows = self._rows(selec, nv)
        dofs = np.arange(nv) if rows is None else rows
        qi = self._qidx[dofs]
        bad = dofs[qi < 0]
        if bad.size:
            joint = self.model.names[_jointOfDof(self.model)[bad[0]]]
            raise SignalTypeError(
                f"{self.selec.name}: DoF {bad[0]} (joint {joint}) is not a one-DoF joint: it "
                "has no joint limit to normalise; deselect it"
            )
        lo, w = l[qi], u[qi] - l[qi]
        badw = ~(np.isfinite(w) & (w > 0) & (np.abs(lo) < 1e300) & (np.abs(u[qi]) < 1e300))
        if badw.any():
            k = int(np.flatnonzero(badw)[0])
            raise SignalTypeError(
                f"{self.name}: DoF {dofs[k]} has limits [{lo[k]:g}, {u[qi][k]:g}]: expected "
                f"finite limits with lowerJl < upperJl ({self.lowerJl.name}, "
                f"{self.upperJl.name}); deselect it in {self.selec.name}"
            )
        return dofs, qi, lo, w

    def _error(
        self,
        selec: Flags,
        q: np.ndarray,
        u: np.ndarray,
        l: np.ndarray,  # noqa: E741
    ) -> np.ndarray:
        if q.shape != (self.model.nq,):
            raise self._sizeError(self.joint, q, f"a configuration of size nq = {self.model.nq}")
        _, qi, lo, w = self._limits(selec, u, l)
        return 2.0 * (q[qi] - lo) / w - 1.0

    def _jacobian(self, selec: Flags, u: np.ndarray, l: np.ndarray) -> np.ndarray:  # noqa: E741
        dofs, _, _, w = self._limits(selec, u, l)
        J = np.zeros((len(dofs), self.model.nv))
        J[np.arange(len(dofs)), dofs] = 2.0 / w
        return J

    @command
    def setThreshold(self, threshold: float) -> None:
        """Normalised distance (in [0, 1)) above which ``activation`` rises from 0."""
        if not 0.0 <= threshold < 1.0:
            raise CommandError(
                f"{self.className}({self.name}).setThreshold: argument 'threshold': "
                f"expected a value in [0, 1), got {threshold}"
            )
        self._threshold = threshold
        self.activation.setReady()

    @command
    def getThreshold(self) -> float:
        """The activation threshold."""
        return self._threshold


# -- FeatureVisualPoint ---------------------------------------------------------------
def interactionMatrix(x: float, y: float, Z: float) -> np.ndarray:
    """Interaction matrix ``L`` (2 x 6) of an image point (Chaumette & Hutchinson).

    ``(x, y)``: normalised image coordinates (``x = X/Z``, ``y = Y/Z`` of the point in
    the camera frame: x right, y down, z along the optical axis), ``Z`` > 0 its depth
    (m). For a fixed point, ``d(x, y)/dt = L (v, w)`` with ``(v, w)`` the camera's
    velocity expressed in the camera frame (Pinocchio's LOCAL twist, linear first).
    """
    iz = 1.0 / Z
    return np.array(
        [
            [-iz, 0.0, x * iz, x * y, -(1.0 + x * x), y],
            [0.0, -iz, y * iz, 1.0 + y * y, -x * y, -x],
        ]
    )


class FeatureVisualPoint(FeatureAbstract):
    """An image point for visual servoing: ``e = (x, y) - (x*, y*)``.

    Inputs: ``xy`` (2: normalised image coordinates ``x = X/Z``, ``y = Y/Z`` of the
    point in the optical frame: x right, y down, z forward), ``Z`` (depth of the point
    in the optical frame, m, > 0), ``Jq`` (6 x nv LOCAL Jacobian of a frame ``f``
    rigidly attached to the camera, e.g. ``dynamic.Jgaze``), ``opticalFrame`` (SE3,
    default identity: the placement ``fMc`` of the optical frame in ``f``; for a frame
    with x forward, y left, z up use ``sotpy.tasks.OPTICAL_FROM_XFORWARD``), and the
    desired point ``xyRef`` (2, default 0), or ``xy`` of a reference feature
    (``setReference(featureDes)``).

    - ``error = xy - xy*`` (no unit);
    - ``jacobian = L(x, y, Z) Ad(fMc^-1) Jq`` with ``L`` :func:`interactionMatrix`
      (the point is fixed in the world);
    - ``errordot = 0``.
    """

    className = "FeatureVisualPoint"

    xy = Input(VECTOR, doc="(x, y): normalised image coordinates of the point")
    Z = Input(DOUBLE, doc="Z: depth of the point in the optical frame (m), > 0")
    Jq = Input(MATRIX, doc="6 x nv LOCAL Jacobian of the camera's frame f")
    xyRef = Input(VECTOR, default=np.zeros(2), doc="(x*, y*): desired image coordinates")
    opticalFrame = Input(
        SE3, default=pin.SE3.Identity(), doc="fMc: optical frame in the frame of Jq"
    )

    _acceptsReferenceFeature = True

    def _errorDeps(self) -> list[Signal]:
        ref = self.xyRef if self._reference is None else self._reference.xy  # type: ignore[attr-defined]
        return [self.selec, self.xy, ref]

    def _jacobianDeps(self) -> list[Signal]:
        return [self.selec, self.xy, self.Z, self.Jq, self.opticalFrame]

    def _checkXy(self, sig: Signal, xy: np.ndarray) -> None:
        if xy.shape != (2,):
            raise self._sizeError(sig, xy, "a vector of size 2 (x, y)")

    def _error(self, selec: Flags, xy: np.ndarray, xydes: np.ndarray) -> np.ndarray:
        self._checkXy(self.xy, xy)
        ref = self.xyRef if self._reference is None else self._reference.xy  # type: ignore[attr-defined]
        self._checkXy(ref, xydes)
        return _take(xy - xydes, self._rows(selec, 2))

    def _jacobian(
        self, selec: Flags, xy: np.ndarray, Z: float, Jq: np.ndarray, fMc: pin.SE3
    ) -> np.ndarray:
        self._checkXy(self.xy, xy)
        if not Z > 0.0:
            raise SignalTypeError(
                f"{self.Z.name}: expected a positive depth (the point in front of the "
                f"camera), got {Z}"
            )
        if Jq.shape[0] != 6:
            raise self._sizeError(self.Jq, Jq, "a 6 x nv Jacobian (LOCAL, linear rows first)")
        L = interactionMatrix(float(xy[0]), float(xy[1]), Z)
        LX = L @ fMc.toActionMatrixInverse()
        return _take(LX, self._rows(selec, 2)) @ Jq


#: ``fMc`` for a camera frame with x forward, y left, z up (ROS body convention, e.g.
#: Talos' ``rgbd_rgb_frame``): the optical axes are x_c = -y_f, y_c = -z_f, z_c = x_f.
OPTICAL_FROM_XFORWARD = pin.SE3(
    np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), np.zeros(3)
)
