"""One BLAS thread for sotpy's control computations.

The matrices of a control tick are small (tens of rows and columns). Multi-threaded
BLAS gains nothing on them and, when the machine is busy, its threads wait for a core:
on this project's 2-core machine, loaded, a Talos SOT tick measured a median of 5.7 to
15 ms with OpenBLAS's default two threads against 1.1 to 1.4 ms with one (see
BENCHMARKS.md). So the first solver created in a process limits the BLAS libraries
loaded by then (numpy's and scipy's OpenBLAS) to one thread, with ``threadpoolctl``.

This is a process-wide setting. ``SOTPY_BLAS_THREADS=n`` (environment) chooses ``n``
threads instead; ``SOTPY_BLAS_THREADS=0`` leaves BLAS as it is.
"""

from __future__ import annotations

import os

from .errors import SotpyError

__all__ = ["limit_blas_threads"]

_applied = False


def limit_blas_threads() -> None:
    """Limit the loaded BLAS libraries to ``SOTPY_BLAS_THREADS`` threads (default 1),
    once per process; later calls do nothing."""
    global _applied
    if _applied:
        return
    _applied = True
    setting = os.environ.get("SOTPY_BLAS_THREADS", "1").strip()
    try:
        n = int(setting)
    except ValueError:
        raise SotpyError(
            f"SOTPY_BLAS_THREADS={setting!r}: expected a number of threads (0: leave BLAS as it is)"
        ) from None
    if n <= 0:
        return
    from threadpoolctl import threadpool_limits

    threadpool_limits(n, user_api="blas")
