"""Value types of signals.

A signal declares one :class:`SignalType`. The type converts values written as
constants (a list becomes a float64 array, an int becomes a float) and refuses what does
not fit, and it decides which plugs are allowed: an output may feed an input of the same
type, and any output may feed an input of type ``any``.

Callbacks are trusted: their results are not converted on the tick's hot path.

The graph core has no robotics in it. Types for robotics objects (``SE3`` for
``pinocchio.SE3``) are made with :func:`object_type` by the layers that need them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

__all__ = [
    "ANY",
    "BOOL",
    "DOUBLE",
    "INT",
    "MATRIX",
    "STRING",
    "VECTOR",
    "SignalType",
    "object_type",
    "type_named",
]


class SignalType:
    """A named value type.

    Args:
        name: the name shown in signal names, e.g. ``vector`` in
            ``Class(e)::input(vector)::x``.
        convert: turns an acceptable value into the stored form, raising
            ``TypeError`` or ``ValueError`` with a short reason otherwise.
        to_array: turns a stored value into a 1-D float array for tracing, or None
            when the type cannot be traced.
    """

    __slots__ = ("convert", "name", "to_array")

    def __init__(
        self,
        name: str,
        convert: Callable[[Any], Any],
        to_array: Callable[[Any], Any] | None = None,
    ) -> None:
        self.name = name
        self.convert = convert
        self.to_array = to_array

    def accepts_output(self, other: SignalType) -> bool:
        """Whether an output of type ``other`` may be plugged into an input of this type."""
        return self is ANY or self is other

    def __repr__(self) -> str:
        return f"SignalType({self.name!r})"


def _np():
    import numpy

    return numpy


def _as_double(v: Any) -> float:
    if isinstance(v, bool) or (not isinstance(v, (int, float)) and not _is_np_real(v)):
        raise TypeError(f"expected a real number, got {type(v).__name__} {v!r}")
    x = float(v)
    if math.isnan(x):
        raise ValueError("expected a real number, got NaN")
    return x


def _is_np_real(v: Any) -> bool:
    np = _np()
    return isinstance(v, (np.floating, np.integer)) or (
        isinstance(v, np.ndarray) and v.shape == () and v.dtype.kind in "fiu"
    )


def _as_int(v: Any) -> int:
    np = _np()
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"expected an integer, got {type(v).__name__} {v!r}")
    return int(v)


def _as_bool(v: Any) -> bool:
    np = _np()
    if not isinstance(v, (bool, np.bool_)):
        raise TypeError(f"expected a bool, got {type(v).__name__} {v!r}")
    return bool(v)


def _as_string(v: Any) -> str:
    if not isinstance(v, str):
        raise TypeError(f"expected a string, got {type(v).__name__} {v!r}")
    return v


def _as_array(v: Any, ndim: int, what: str):
    np = _np()
    if isinstance(v, (str, bytes)):
        raise TypeError(f"expected a {what}, got a string {v!r}")
    try:
        a = np.array(v, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"expected a {what} of real numbers, got {v!r}") from exc
    if a.ndim != ndim:
        raise ValueError(f"expected a {what} ({ndim}-D array), got shape {a.shape}")
    if np.isnan(a).any():
        raise ValueError(f"expected a {what} without NaN, got {v!r}")
    return a


def _vector(v: Any):
    return _as_array(v, 1, "vector")


def _matrix(v: Any):
    return _as_array(v, 2, "matrix")


def _scalar_row(v: Any):
    return _np().array([float(v)])


def _ravel(v: Any):
    return _np().asarray(v, dtype=float).ravel()


DOUBLE = SignalType("double", _as_double, _scalar_row)
INT = SignalType("int", _as_int, _scalar_row)
BOOL = SignalType("bool", _as_bool, _scalar_row)
STRING = SignalType("string", _as_string, None)
VECTOR = SignalType("vector", _vector, _ravel)
MATRIX = SignalType("matrix", _matrix, _ravel)
ANY = SignalType("any", lambda v: v, None)

_BY_NAME: dict[str, SignalType] = {
    t.name: t for t in (DOUBLE, INT, BOOL, STRING, VECTOR, MATRIX, ANY)
}


def object_type(name: str, cls: type, to_array: Callable[[Any], Any] | None = None) -> SignalType:
    """Make (once) and return the signal type of instances of ``cls``.

    Calling it again with the same name returns the same type object, so two layers
    that declare ``object_type("SE3", pinocchio.SE3)`` can plug into each other.
    """
    existing = _BY_NAME.get(name)
    if existing is not None:
        return existing

    def convert(v: Any) -> Any:
        if not isinstance(v, cls):
            raise TypeError(f"expected {cls.__module__}.{cls.__qualname__}, got {type(v).__name__}")
        return v.copy() if hasattr(v, "copy") else v

    t = SignalType(name, convert, to_array)
    _BY_NAME[name] = t
    return t


def type_named(name: str | SignalType) -> SignalType:
    """Return the type called ``name`` (``double``, ``vector``, ...), or ``name`` itself."""
    if isinstance(name, SignalType):
        return name
    try:
        return _BY_NAME[name]
    except KeyError:
        raise ValueError(
            f"unknown signal type {name!r}; known types: {', '.join(sorted(_BY_NAME))}"
        ) from None
