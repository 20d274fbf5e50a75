r"""Task rows written straight into a solver's stacked buffer: the SOT's fused
evaluation of its equality tasks.

At every tick an SOT needs, for each task, ``J`` (``m x nv``) and the target
``-lambda e``. Through the signals that is one plan step per feature output and per
task output (about twenty for a stand-and-reach stack), each building its own arrays.
A :class:`RowWriter` computes the same numbers from the signals those outputs read
(the features' inputs: placements, Jacobians, selections, references; the task's
gain and column selection) and writes them into rows of one buffer: one compiled call
per :class:`~sotpy.tasks.features.FeaturePose`,
:class:`~sotpy.tasks.features.FeatureGeneric` or
:class:`~sotpy.tasks.features.FeaturePosture` (the kernels of ``_rowkernels``), the feature's
own callbacks for any other feature.

Rules that keep it exact (see ``docs/tasks.md``):

* a writer is made only for outputs that compute with their entity's own callback,
  every tick (period 1, not set to a constant, no replaced callback); otherwise the
  SOT reads the task's signals;
* a writer reads exactly the signals the bypassed callbacks would read (the plan
  brings them up to date), so it sees the same inputs at the same tick;
* a writer answers ``-1`` for anything it does not recognise (a shape, a type, a
  gain out of range): the SOT then reads the task signals for that tick, whose
  callbacks raise the errors that name the task and the feature;
* the bypassed signals keep their callbacks: reading one (the shell, a tracer, a
  ``GainAdaptive``) computes it as before.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..graph.signal import FUNCTION, OutputSignal, Signal

__all__ = ["BufferFull", "RowWriter", "WriteFn", "callbackWriter", "computedByOwnCallback"]

#: ``write(values, offset, A, b, r, gain) -> rows written, or -1``: ``values[offset:]``
#: are the values of the writer's sources, in order; rows go to ``A[r:]``, ``b[r:]``.
WriteFn = Callable[[Sequence[Any], int, np.ndarray, np.ndarray, int, float], int]


class BufferFull(Exception):
    """Raised by a writer whose rows do not fit in the buffer (the caller grows it and
    writes again)."""


class RowWriter:
    """How to write some rows (a feature's or a task's) into a stacked buffer.

    Attributes:
        sources: the signals (holders: a plugged input's source) whose values
            ``write`` receives, in order.
        write: see :data:`WriteFn`; ``gain`` is the task's ``lambda`` (1/s): a
            feature writes ``J_k`` into ``A[r + i]`` and ``-gain e_k`` into ``b[r + i]``
            for its ``i``-th selected row ``k``.
    """

    __slots__ = ("sources", "write")

    def __init__(self, sources: Sequence[Signal], write: WriteFn) -> None:
        self.sources = tuple(s._holder() for s in sources)
        self.write = write

    def __len__(self) -> int:
        return len(self.sources)


def computedByOwnCallback(sig: OutputSignal, fn: Callable[..., Any]) -> bool:
    """Whether ``sig`` computes at every tick with the method ``fn`` of its entity
    (not a constant, not a replaced callback, not periodic, no time argument)."""
    f = sig._fn
    return (
        sig._mode == FUNCTION
        and sig.period == 1
        and not sig._withTime
        and getattr(f, "__func__", None) is fn
        and getattr(f, "__self__", None) is sig.entity
    )


def callbackWriter(error: OutputSignal, jacobian: OutputSignal) -> RowWriter | None:
    """A writer that calls a feature's own ``error`` and ``jacobian`` callbacks (any
    feature class) and copies the rows; None if either output is not computed by a
    callback at every tick."""
    for sig in (error, jacobian):
        if sig._mode != FUNCTION or sig.period != 1 or sig._withTime:
            return None
    fe, fj = error._fn, jacobian._fn
    ne, nj = len(error._srcs), len(jacobian._srcs)

    def write(v: Sequence[Any], o: int, A: np.ndarray, b: np.ndarray, r: int, gain: float) -> int:
        e = fe(*v[o : o + ne])
        J = fj(*v[o + ne : o + ne + nj])
        if (
            type(e) is not np.ndarray
            or type(J) is not np.ndarray
            or e.ndim != 1
            or J.shape != (e.shape[0], A.shape[1])
        ):
            return -1
        k = e.shape[0]
        if r + k > A.shape[0]:
            raise BufferFull
        A[r : r + k] = J
        np.multiply(e, -gain, out=b[r : r + k])
        return k

    return RowWriter((*error._srcs, *jacobian._srcs), write)
