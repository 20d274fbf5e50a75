"""Compiled kernels: numba when it is installed and not disabled.

A few per-tick numerical kernels (the whole-body QP's reduction and active-set solve)
are small dense linear algebra wrapped in many NumPy calls; at 1 kHz the calls cost
more than the arithmetic. With numba they run as one compiled function each, calling
the same LAPACK/BLAS. Every kernel has a NumPy twin used when numba is missing or
``SOTPY_JIT=0`` is set, and the tests compare the two.

Kernels are compiled on first use and cached on disk (numba's ``cache=True``: next to
the module, or in numba's user cache when that is not writable), so only the first run
on a machine pays the compilation (tens of seconds on a slow machine).
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])

try:  # pragma: no cover - exercised by the environment, not by a test
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None

#: Whether compiled kernels are used (numba importable and ``SOTPY_JIT`` not ``0``).
ENABLED: bool = _numba is not None and os.environ.get("SOTPY_JIT", "1") != "0"


def kernel(fn: F) -> F | None:
    """``numba.njit(cache=True)`` of ``fn`` when :data:`ENABLED`, else ``None`` (the
    caller then uses its NumPy twin)."""
    if not ENABLED:
        return None
    return _numba.njit(cache=True, nogil=True)(fn)


def report_compile(what: str, seconds: float) -> None:
    """Say on stderr that ``what`` was compiled (not loaded from the cache) when that
    took long enough to be noticed; a first run on a machine is otherwise a silent
    pause."""
    if seconds > 3.0:
        print(
            f"sotpy: compiled {what} in {seconds:.0f} s (first use on this machine;"
            " cached for the next runs)",
            file=sys.stderr,
        )


def refused(owner: str, exc: Exception) -> None:
    """Warn that ``owner``'s compiled kernels refused their arguments (types they were
    not compiled for, compilation being frozen after the warm-up) and that it uses its
    NumPy path from now on."""
    from .errors import SotpyWarning

    warnings.warn(
        f"{owner}: compiled kernels refused the data ({exc}); NumPy from now on",
        SotpyWarning,
        stacklevel=4,
    )


def c_float64(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous float64 array (itself when it already is: the usual case,
    checked without a copy), the layout the kernels were compiled for."""
    if a.dtype == np.float64 and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, dtype=np.float64)
