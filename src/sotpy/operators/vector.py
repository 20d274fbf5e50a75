"""Vector operators: selection, stacking, sums, differences, products and constants.

SoT's ``sot-core/src/matrix/operator.cpp`` entities, with their class, signal and
command names (``docs/operators.md`` has the reference and the deviations):

==========================  ============================  ==================================
class                       signals                       sout
==========================  ============================  ==================================
``Selec_of_vector``         sin -> sout                   ``sin[imin:imax]`` (+ ``addSelec``)
``Component_of_vector``     sin -> sout (double)          ``sin[index]``
``Stack_of_vector``         sin1, sin2 -> sout            ``(sin1[a:b], sin2[c:d])``
``Add_of_vector``           sin0..sin{n-1} -> sout        ``sum_i coeffs[i] sin_i``
``Add_of_double/_matrix``   sin0..sin{n-1} -> sout        idem, doubles / matrices
``Substract_of_vector``     sin1, sin2 -> sout            ``sin1 - sin2`` (also double, matrix)
``Multiply_matrix_vector``  sin1 (matrix), sin2 -> sout   ``sin1 @ sin2``
``Multiply_double_vector``  sin1 (double), sin2 -> sout   ``sin1 * sin2``
``Multiply_of_double``      sin0..sin{n-1} -> sout        ``sin0 * sin1 * ...`` (doubles)
``VectorConstant``          sout                          the vector given to ``set``
``MatrixConstant``          sout                          the matrix given to ``set``
==========================  ============================  ==================================

Every input size is checked when the output is computed: a mismatch raises
:class:`~sotpy.errors.SignalTypeError` naming the signal and the expected size (numpy
would broadcast some of them into a silently wrong value). Outputs are fresh arrays,
never views of an input.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from ..errors import CommandError, SignalTypeError, SotpyError
from ..graph import DOUBLE, MATRIX, VECTOR, Entity, Input, Output, SignalType, command
from ..graph.signal import InputSignal
from ._util import check_index_range, check_matrix, check_vector, received, who

__all__ = [
    "Add_of_double",
    "Add_of_matrix",
    "Add_of_vector",
    "Component_of_vector",
    "MatrixConstant",
    "Multiply_double_vector",
    "Multiply_matrix_vector",
    "Multiply_of_double",
    "Selec_of_vector",
    "Stack_of_vector",
    "Substract_of_double",
    "Substract_of_matrix",
    "Substract_of_vector",
    "VariadicOp",
    "VectorConstant",
]


# -- selections --------------------------------------------------------------------------
class Selec_of_vector(Entity):
    """Select segments of a vector: ``sout = (sin[m0:M0], sin[m1:M1], ...)``.

    ``selec(imin, imax)`` sets one half-open segment ``[imin, imax)``;
    ``addSelec(imin, imax)`` appends another. Reading ``sout`` before any ``selec``
    raises (SoT returned an empty vector); a segment past the end of ``sin`` raises
    naming the sizes.
    """

    sin = Input(VECTOR, doc="vector to select from (any unit)")

    def __init__(self, name: str) -> None:
        self._segments: list[tuple[int, int]] | None = None

    @Output(VECTOR, deps=("sin",), doc="the selected entries, in segment order")
    def sout(self, x: np.ndarray) -> np.ndarray:
        segs = self._segments
        if segs is None:
            raise SotpyError(
                f"{self.sout.name}: no selection: call {self.name}.selec(imin, imax) first"
            )
        check_vector(self.sin, x)
        end = max((b for _, b in segs), default=0)
        if end > x.shape[0]:
            bad = next((a, b) for a, b in segs if b > x.shape[0])
            raise SignalTypeError(
                f"{self.sin.name}: the selection [{bad[0]}, {bad[1]}) needs a vector of size "
                f">= {bad[1]}, received size {x.shape[0]}"
            )
        if len(segs) == 1:
            a, b = segs[0]
            return x[a:b].copy()
        return np.concatenate([x[a:b] for a, b in segs])

    @command
    def selec(self, imin: int, imax: int) -> None:
        """Select the half-open segment ``[imin, imax)`` (replaces every segment)."""
        check_index_range(self, "selec", imin, imax)
        self._segments = [(imin, imax)]
        self.sout.setReady()

    @command
    def addSelec(self, imin: int, imax: int) -> None:
        """Append the half-open segment ``[imin, imax)`` to the selection."""
        check_index_range(self, "addSelec", imin, imax)
        self._segments = [*(self._segments or []), (imin, imax)]
        self.sout.setReady()


class Component_of_vector(Entity):
    """One entry of a vector as a double: ``sout = sin[index]``.

    ``setIndex(i)`` chooses the entry; reading ``sout`` before raises (SoT's index was
    uninitialised), and so does an index past the end of ``sin``.
    """

    sin = Input(VECTOR, doc="vector (any unit)")

    def __init__(self, name: str) -> None:
        self._index: int | None = None

    @Output(DOUBLE, deps=("sin",), doc="sin[index], same unit")
    def sout(self, x: np.ndarray) -> float:
        i = self._index
        if i is None:
            raise SotpyError(f"{self.sout.name}: no index: call {self.name}.setIndex(i) first")
        check_vector(self.sin, x)
        if i >= x.shape[0]:
            raise SignalTypeError(
                f"{self.sin.name}: index {i} needs a vector of size >= {i + 1}, received "
                f"size {x.shape[0]}"
            )
        return float(x[i])

    @command
    def setIndex(self, index: int) -> None:
        """Select entry ``index`` (>= 0) of ``sin``."""
        if index < 0:
            raise CommandError(f"{who(self, 'setIndex')}: expected an index >= 0, got {index}")
        self._index = index
        self.sout.setReady()


class Stack_of_vector(Entity):
    """Stack two vectors: ``sout = (sin1[a:b], sin2[c:d])``.

    ``selec1(a, b)`` and ``selec2(c, d)`` choose half-open segments of each input;
    without them the whole input is stacked (SoT's bounds were uninitialised).
    """

    sin1 = Input(VECTOR, doc="first vector")
    sin2 = Input(VECTOR, doc="second vector")

    def __init__(self, name: str) -> None:
        self._sel: list[tuple[int, int] | None] = [None, None]

    @Output(VECTOR, deps=("sin1", "sin2"), doc="sin1[a:b] then sin2[c:d]")
    def sout(self, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
        parts = []
        for sig, x, sel, cmd in (
            (self.sin1, x1, self._sel[0], "selec1"),
            (self.sin2, x2, self._sel[1], "selec2"),
        ):
            check_vector(sig, x)
            if sel is None:
                parts.append(x)
                continue
            a, b = sel
            if b > x.shape[0]:
                raise SignalTypeError(
                    f"{sig.name}: {cmd}({a}, {b}) needs a vector of size >= {b}, received "
                    f"size {x.shape[0]}"
                )
            parts.append(x[a:b])
        return np.concatenate(parts)

    @command
    def selec1(self, imin: int, imax: int) -> None:
        """Take ``sin1[imin:imax]`` (half-open)."""
        check_index_range(self, "selec1", imin, imax)
        self._sel[0] = (imin, imax)
        self.sout.setReady()

    @command
    def selec2(self, imin: int, imax: int) -> None:
        """Take ``sin2[imin:imax]`` (half-open)."""
        check_index_range(self, "selec2", imin, imax)
        self._sel[1] = (imin, imax)
        self.sout.setReady()


# -- variadic operators -------------------------------------------------------------------
class VariadicOp:
    """Mixin for SoT's variadic operators: inputs ``sin0 .. sin{n-1}`` and ``sout``.

    ``setSignalNumber(n)`` creates or removes inputs (removed inputs are unplugged),
    ``getSignalNumber()`` and the property ``n_sin`` give ``n``, and ``sin(i)`` returns
    input ``i`` (as in sot-core's Python bindings). A class using it declares
    ``_inType`` (the inputs' type), an output ``sout`` declared with
    ``timeDependent=False`` whose callback takes ``(*leading, *inputs)``, and optionally
    ``_leadingDeps()`` (signals read before the inputs, e.g. a switch's selection).
    """

    _inType: ClassVar[SignalType]
    _inDoc: ClassVar[str] = "operand"
    _defaultSignalNumber: ClassVar[int] = 2

    def _initVariadic(self) -> None:
        self._nsin = 0
        self._sins: list[InputSignal] = []
        self.setSignalNumber(self._defaultSignalNumber)  # type: ignore[attr-defined]

    def _leadingDeps(self) -> list[Any]:
        return []

    def _inputs(self) -> list[InputSignal]:
        """``[sin0, ..., sin{n-1}]`` (kept by :meth:`setSignalNumber`)."""
        return self._sins  # type: ignore[return-value]

    def _updateDependencies(self) -> None:
        self.sout.setDependencies([*self._leadingDeps(), *self._inputs()])  # type: ignore[attr-defined]

    def _updateSignalNumber(self, n: int) -> None:
        """Hook: the number of inputs changed to ``n``."""

    @command
    def setSignalNumber(self, n: int) -> None:
        """Set the number of inputs to ``n`` (>= 0): inputs ``sin0 .. sin{n-1}``.

        New inputs are unset; removed ones are unplugged first."""
        if n < 0:
            raise CommandError(
                f"{who(self, 'setSignalNumber')}: expected a number of inputs >= 0, got {n}"
            )
        old = self._nsin
        for i in range(old - 1, n - 1, -1):
            self.removeSignal(f"sin{i}")  # type: ignore[attr-defined]
        for i in range(old, n):
            self.addSignal(InputSignal(self, f"sin{i}", self._inType, doc=f"{self._inDoc} {i}"))  # type: ignore[attr-defined, arg-type]
        self._nsin = n
        self._sins = [self.signal(f"sin{i}") for i in range(n)]  # type: ignore[attr-defined]
        self._updateSignalNumber(n)
        self._updateDependencies()

    @command
    def getSignalNumber(self) -> int:
        """The number of inputs ``n`` (``sin0 .. sin{n-1}``)."""
        return self._nsin

    @command
    def sin(self, i: int) -> InputSignal:
        """Input ``i`` (``sin{i}``), as sot-core's ``op.sin(i)``."""
        if not 0 <= i < self._nsin:
            raise CommandError(
                f"{who(self, 'sin')}: expected an input index in 0..{self._nsin - 1} "
                f"(setSignalNumber sets the number of inputs), got {i}"
            )
        return self.signal(f"sin{i}")  # type: ignore[attr-defined, return-value]

    @property
    def n_sin(self) -> int:
        """The number of inputs (settable: same as ``setSignalNumber``)."""
        return self._nsin

    @n_sin.setter
    def n_sin(self, n: int) -> None:
        self.setSignalNumber(n)


class _Adder(VariadicOp):
    """``sout = sum_i coeffs[i] * sin_i`` (SoT's ``AdderVariadic``)."""

    def _initAdder(self) -> None:
        self._coeffs = np.ones(0)
        self._initVariadic()

    def _updateSignalNumber(self, n: int) -> None:
        # Keep the coefficients of the inputs that remain; new inputs get 1 (sot-core
        # reset every coefficient to 1).
        c = np.ones(n)
        k = min(n, self._coeffs.shape[0])
        c[:k] = self._coeffs[:k]
        self._coeffs = c

    @command
    def setCoeffs(self, coeffs: np.ndarray) -> None:
        """Set the coefficients (one per input, no unit): ``sout = sum coeffs[i] sin_i``."""
        c = np.asarray(coeffs, dtype=float)
        if c.ndim != 1 or c.shape[0] != self._nsin:
            raise CommandError(
                f"{who(self, 'setCoeffs')}: expected {self._nsin} coefficients (one per "
                f"input; setSignalNumber changes the number), got {received(c)}"
            )
        if not np.isfinite(c).all():
            raise CommandError(f"{who(self, 'setCoeffs')}: coefficients must be finite: {c}")
        self._coeffs = c.copy()
        self.sout.setReady()  # type: ignore[attr-defined]

    @property
    def coeffs(self) -> np.ndarray:
        """The coefficients (a copy; assign to set them, as in sot-core)."""
        return self._coeffs.copy()

    @coeffs.setter
    def coeffs(self, value: Any) -> None:
        self.setCoeffs(value)  # type: ignore[arg-type]

    def _noInput(self) -> SotpyError:
        return SotpyError(
            f"{self.sout.name}: the sum has no input: call {self.name}.setSignalNumber(n) "  # type: ignore[attr-defined]
            "with n >= 1"
        )


class Add_of_vector(_Adder, Entity):
    """Weighted sum of vectors: ``sout = sum_i coeffs[i] * sin_i``.

    Two inputs by default (``sin0``, ``sin1``), coefficients 1. Every input must have
    the size of ``sin0``.
    """

    _inType = VECTOR
    _inDoc = "vector"

    def __init__(self, name: str) -> None:
        self._initAdder()

    @Output(VECTOR, timeDependent=False, doc="sum_i coeffs[i] * sin_i")
    def sout(self, *xs: np.ndarray) -> np.ndarray:
        if not xs:
            raise self._noInput()
        sigs = self._inputs()
        n = check_vector(sigs[0], xs[0]).shape[0]
        c = self._coeffs
        out = c[0] * xs[0]
        for i in range(1, len(xs)):
            out += c[i] * check_vector(sigs[i], xs[i], n, "the size of sin0")
        return out


class Add_of_double(_Adder, Entity):
    """Weighted sum of doubles: ``sout = sum_i coeffs[i] * sin_i``."""

    _inType = DOUBLE
    _inDoc = "double"

    def __init__(self, name: str) -> None:
        self._initAdder()

    @Output(DOUBLE, timeDependent=False, doc="sum_i coeffs[i] * sin_i")
    def sout(self, *xs: float) -> float:
        if not xs:
            raise self._noInput()
        return float(np.dot(self._coeffs, xs))


class Add_of_matrix(_Adder, Entity):
    """Weighted sum of matrices: ``sout = sum_i coeffs[i] * sin_i`` (same shapes)."""

    _inType = MATRIX
    _inDoc = "matrix"

    def __init__(self, name: str) -> None:
        self._initAdder()

    @Output(MATRIX, timeDependent=False, doc="sum_i coeffs[i] * sin_i")
    def sout(self, *xs: np.ndarray) -> np.ndarray:
        if not xs:
            raise self._noInput()
        sigs = self._inputs()
        shape = check_matrix(sigs[0], xs[0]).shape
        c = self._coeffs
        out = c[0] * xs[0]
        for i in range(1, len(xs)):
            out += c[i] * check_matrix(sigs[i], xs[i], shape, "the shape of sin0")
        return out


# -- binary operators ---------------------------------------------------------------------
class Substract_of_vector(Entity):
    """Difference of two vectors of the same size: ``sout = sin1 - sin2``."""

    sin1 = Input(VECTOR, doc="minuend")
    sin2 = Input(VECTOR, doc="subtrahend (size of sin1)")

    @Output(VECTOR, deps=("sin1", "sin2"), doc="sin1 - sin2")
    def sout(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        n = check_vector(self.sin1, a).shape[0]
        check_vector(self.sin2, b, n, "the size of sin1")
        return a - b


class Substract_of_double(Entity):
    """Difference of two doubles: ``sout = sin1 - sin2``."""

    sin1 = Input(DOUBLE, doc="minuend")
    sin2 = Input(DOUBLE, doc="subtrahend")

    @Output(DOUBLE, deps=("sin1", "sin2"), doc="sin1 - sin2")
    def sout(self, a: float, b: float) -> float:
        return a - b


class Substract_of_matrix(Entity):
    """Difference of two matrices of the same shape: ``sout = sin1 - sin2``."""

    sin1 = Input(MATRIX, doc="minuend")
    sin2 = Input(MATRIX, doc="subtrahend (shape of sin1)")

    @Output(MATRIX, deps=("sin1", "sin2"), doc="sin1 - sin2")
    def sout(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        shape = check_matrix(self.sin1, a).shape
        check_matrix(self.sin2, b, shape, "the shape of sin1")
        return a - b


class Multiply_matrix_vector(Entity):
    """Matrix-vector product: ``sout = sin1 @ sin2`` (``m x n`` times size ``n``)."""

    sin1 = Input(MATRIX, doc="matrix A (m x n)")
    sin2 = Input(VECTOR, doc="vector x (size n)")

    @Output(VECTOR, deps=("sin1", "sin2"), doc="A x (size m)")
    def sout(self, A: np.ndarray, x: np.ndarray) -> np.ndarray:
        n = check_matrix(self.sin1, A).shape[1]
        check_vector(self.sin2, x, n, "the number of columns of sin1")
        return A @ x


class Multiply_double_vector(Entity):
    """Scalar times vector: ``sout = sin1 * sin2``."""

    sin1 = Input(DOUBLE, doc="scalar k")
    sin2 = Input(VECTOR, doc="vector x")

    @Output(VECTOR, deps=("sin1", "sin2"), doc="k x")
    def sout(self, k: float, x: np.ndarray) -> np.ndarray:
        check_vector(self.sin2, x)
        return k * x


class Multiply_of_double(VariadicOp, Entity):
    """Product of doubles: ``sout = sin0 * sin1 * ... * sin{n-1}`` (1 if n = 0)."""

    _inType = DOUBLE
    _inDoc = "factor"

    def __init__(self, name: str) -> None:
        self._initVariadic()

    @Output(DOUBLE, timeDependent=False, doc="sin0 * sin1 * ...")
    def sout(self, *xs: float) -> float:
        out = 1.0
        for x in xs:
            out *= x
        return out


# -- constants ----------------------------------------------------------------------------
class VectorConstant(Entity):
    """A constant vector: ``sout`` is the vector given to ``set`` (or zeros after
    ``resize(n)``). Reading ``sout`` before either raises."""

    def __init__(self, name: str) -> None:
        self._value: np.ndarray | None = None

    @Output(VECTOR, timeDependent=False, doc="the constant vector")
    def sout(self) -> np.ndarray:
        if self._value is None:
            raise SotpyError(
                f"{self.sout.name}: no value: call {self.name}.set(vector) or "
                f"{self.name}.resize(n) first"
            )
        return self._value.copy()

    @command
    def resize(self, n: int) -> None:
        """Make ``sout`` the zero vector of size ``n`` (>= 0)."""
        if n < 0:
            raise CommandError(f"{who(self, 'resize')}: expected a size >= 0, got {n}")
        self._value = np.zeros(n)
        self.sout.setReady()

    @command
    def set(self, value: VECTOR) -> None:  # type: ignore[valid-type]
        """Make ``sout`` the vector ``value``."""
        self._value = np.array(value, dtype=float)
        self.sout.setReady()


class MatrixConstant(Entity):
    """A constant matrix: ``sout`` is the matrix given to ``set`` (or zeros after
    ``resize(rows, cols)``). Reading ``sout`` before either raises."""

    def __init__(self, name: str) -> None:
        self._value: np.ndarray | None = None

    @Output(MATRIX, timeDependent=False, doc="the constant matrix")
    def sout(self) -> np.ndarray:
        if self._value is None:
            raise SotpyError(
                f"{self.sout.name}: no value: call {self.name}.set(matrix) or "
                f"{self.name}.resize(rows, cols) first"
            )
        return self._value.copy()

    @command
    def resize(self, rows: int, cols: int) -> None:
        """Make ``sout`` the zero matrix of ``rows`` x ``cols`` (>= 0)."""
        if rows < 0 or cols < 0:
            raise CommandError(f"{who(self, 'resize')}: expected sizes >= 0, got {rows} x {cols}")
        self._value = np.zeros((rows, cols))
        self.sout.setReady()

    @command
    def set(self, value: MATRIX) -> None:  # type: ignore[valid-type]
        """Make ``sout`` the matrix ``value`` (a 2-D array or a tuple of rows)."""
        self._value = np.array(value, dtype=float)
        self.sout.setReady()
