r"""Task rows written straight into a solver's stacked buffer: the SOT's fused
evaluation of its stack.

At every tick an SOT needs, for each task, ``J`` (``m x nv``) and the target
``-lambda e`` (or, for an inequality task, its bounds). Through the signals that is one
plan step per feature output and per task output (about twenty for a stand-and-reach
stack), each building its own arrays. A :class:`RowProgram` computes the same numbers
from the signals those outputs read (the features' inputs: placements, Jacobians,
selections, references; the task's gain, references and column selection) and writes
every level, the joint limits included, into the solver's buffers in **one** call of
a compiled kernel (``sotpy.tasks._rowkernels.write_rows``).

A program is a list of :class:`RowOp`: one per feature (its rows and error), one per
task (its gain or bounds, closing its level), one for the joint limits and one for
each task read through its signals. Each operation hands the kernel a few arrays:
its *gather*, a small Python function called at every tick, takes them from the
signal values (``M.homogeneous``, a Jacobian, a selection's indices) and puts them in
the call's argument list; nothing is copied. Measured on the tutorial's humanoid
graph (docs/tutorial-reach.md): one kernel call per feature and per task, with each
writer's Python checks, cost 21 us of a 96 us tick; the program costs about 13 us
(BENCHMARKS.md, "One call for the task rows").

Rules that keep it exact (see ``docs/tasks.md``):

* an operation is made only for outputs that compute with their entity's own
  callback, every tick (period 1, not set to a constant, no replaced callback);
  otherwise the task is read through its signals (a ``LEVEL`` operation);
* an operation reads exactly the signals the bypassed callbacks would read (the plan
  brings them up to date), so it sees the same inputs at the same tick;
* anything a gather or the kernel does not recognise (a type, a shape, a gain out of
  range, a value that is not finite) makes the program answer
  ``_rowkernels.REFUSED``: the SOT then reads the task signals for
  that tick, whose callbacks raise the errors that name the task and the feature;
* the bypassed signals keep their callbacks: reading one (the shell, a tracer, a
  ``GainAdaptive``) computes it as before.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..graph.signal import FUNCTION, OutputSignal, Signal
from . import _rowkernels as rk

__all__ = [
    "ALL_COLUMNS",
    "CALLBACK_ROWS",
    "Gather",
    "RowOp",
    "RowProgram",
    "callbackOp",
    "computedByOwnCallback",
    "levelOp",
]

#: ``gather(values, offset, args, scal, n) -> ok``: put this tick's arrays in ``args``
#: and scalars in ``scal`` (at the positions given to ``bind``), from ``values[offset:]``
#: (the values of the operation's sources, in order); ``n`` is the number of columns.
#: False when a value is not what the operation expects (the signals then decide).
Gather = Callable[[Sequence[Any], int, list[Any], np.ndarray, int], bool]

#: The index vector ``[-1]``: a task's column selection meaning "every column"
#: (``ALL_COLUMNS``), and a ``POSTURE`` operation whose rows its callbacks computed
#: (``CALLBACK_ROWS``).
ALL_COLUMNS = CALLBACK_ROWS = np.full(1, -1, dtype=np.int64)
ALL_COLUMNS.flags.writeable = False

_GROUPS = {"m": 0, "v": rk.MATS, "i": rk.MATS + rk.VECS}
_SIZES = {"m": rk.MATS, "v": rk.VECS, "i": rk.INTS}


class RowOp:
    """One operation of a :class:`RowProgram`.

    Attributes:
        kind: the kernel's operation (``_rowkernels.POSE``, ``GENERIC``, ``POSTURE``,
            ``ROWS``, ``EQUALITY``, ``INEQUALITY``, ``LIMITS``, ``LEVEL``).
        spec: what it hands the kernel, in the order of the operation's fields: ``m`` a
            matrix, ``v`` a vector, ``i`` an index vector, ``s`` a scalar. A field past
            the spec is absent (``-1``).
        sources: the signals (holders: a plugged input's source) whose values the
            gather reads, in order.
        bind: ``bind(positions) -> gather``: given where each field goes (its index in
            the call's argument list, or in ``scal`` for a scalar), the function that
            fills them at every tick (see :data:`Gather`).
        closes: whether it ends a level (a task's or a level's operation).
    """

    __slots__ = ("bind", "closes", "kind", "sources", "spec")

    def __init__(
        self,
        kind: int,
        spec: str,
        sources: Sequence[Signal],
        bind: Callable[[tuple[int, ...]], Gather],
    ) -> None:
        self.kind = kind
        self.spec = spec
        self.sources = tuple(s._holder() for s in sources)
        self.bind = bind
        self.closes = kind in (rk.EQUALITY, rk.INEQUALITY, rk.LIMITS, rk.LEVEL)

    def __len__(self) -> int:
        return len(self.sources)

    def __repr__(self) -> str:
        return f"<RowOp {_KINDS[self.kind]} {self.spec} of {len(self.sources)} sources>"


_KINDS = ("POSE", "GENERIC", "POSTURE", "ROWS", "EQUALITY", "INEQUALITY", "LIMITS", "LEVEL")


class RowProgram:
    """Operations run by the compiled kernel, one call per group of operations whose
    arrays fit its argument list (``_rowkernels.MATS`` matrices, ``VECS`` vectors,
    ``INTS`` index vectors): one call for a stack of a few tasks.

    Attributes:
        sources: every operation's sources, in order (``run`` takes their values).
        levels: the number of levels the operations close.
    """

    def __init__(self, ops: Sequence[RowOp]) -> None:
        self.ops = tuple(ops)
        self.sources: tuple[Signal, ...] = tuple(s for op in self.ops for s in op.sources)
        self.levels = sum(op.closes for op in self.ops)
        nscal = sum(op.spec.count("s") for op in self.ops)
        self._scal = np.zeros(max(nscal, 1))
        self._state = np.zeros(3, dtype=np.int64)
        calls: list[tuple[list[list[int]], list[tuple[Gather, int]]]] = []
        used: dict[str, int] = {}
        offset = nscal = 0
        for op in self.ops:
            if not calls or any(used[g] + op.spec.count(g) > _SIZES[g] for g in _SIZES):
                calls.append(([], []))  # a new call of the kernel
                used = dict.fromkeys(_SIZES, 0)
            fields, positions = [], []
            for letter in op.spec:
                if letter == "s":
                    fields.append(nscal)
                    positions.append(nscal)
                    nscal += 1
                else:
                    fields.append(used[letter])
                    positions.append(_GROUPS[letter] + used[letter])
                    used[letter] += 1
            calls[-1][0].append([op.kind, *fields] + [-1] * (rk.FIELDS - 1 - len(fields)))
            calls[-1][1].append((op.bind(tuple(positions)), offset))
            offset += len(op)
        # each call: its code, its gathers and its argument list (padded once; the
        # gathers overwrite their positions at every tick)
        self._calls = [
            (np.array(code, dtype=np.int64), gathers, list(rk.PAD)) for code, gathers in calls
        ]

    def run(
        self,
        values: Sequence[Any],
        A: np.ndarray,
        lo: np.ndarray,
        up: np.ndarray,
        ends: np.ndarray,
        fixed: bool,
        offset: int = 0,
    ) -> int:
        """Write the rows from row 0 of ``A``, ``lo`` and ``up`` (``values[offset:]``:
        the values of :attr:`sources`). Level ``k`` ends at row ``ends[k]``: written
        there, or with ``fixed`` checked against it.

        Returns the number of rows written, or ``_rowkernels.REFUSED`` (a value the
        signals' callbacks must judge), ``NO_ROOM`` (``A`` too short) or ``RESIZED``
        (a level's size is not ``ends``'s)."""
        scal, state, n = self._scal, self._state, A.shape[1]
        state.fill(0)
        write = rk.write_rows
        r = 0
        for code, gathers, args in self._calls:
            for gather, o in gathers:
                if not gather(values, offset + o, args, scal, n):
                    return rk.REFUSED
            r = write(code, scal, state, A, lo, up, ends, fixed, *args)
            if r < 0:
                return r
        return r


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


def callbackOp(error: OutputSignal, jacobian: OutputSignal) -> RowOp | None:
    """A ``ROWS`` operation that calls a feature's own ``error`` and ``jacobian``
    callbacks (any feature class) and copies their rows; None if either output is not
    computed by a callback at every tick."""
    for sig in (error, jacobian):
        if sig._mode != FUNCTION or sig.period != 1 or sig._withTime:
            return None
    fe, fj = error._fn, jacobian._fn
    ne, nj = len(error._srcs), len(jacobian._srcs)

    def bind(at: tuple[int, ...]) -> Gather:
        aJ, ae = at

        def gather(v: Sequence[Any], o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
            e = fe(*v[o : o + ne])
            J = fj(*v[o + ne : o + ne + nj])
            if not (_floats(e, 1) and _floats(J, 2)):
                return False
            args[aJ], args[ae] = J, e
            return True

        return gather

    return RowOp(rk.ROWS, "mv", (*error._srcs, *jacobian._srcs), bind)


def _floats(a: Any, ndim: int) -> bool:
    """Whether ``a`` is a float64 array of ``ndim`` dimensions (what the kernel takes)."""
    return type(a) is np.ndarray and a.ndim == ndim and a.dtype.char == "d"


def levelOp(J: Signal, lower: Signal, upper: Signal) -> RowOp:
    """A ``LEVEL`` operation: a task read through its signals (``J``, and its bounds;
    an equality task's target twice), copied into its level."""

    def bind(at: tuple[int, ...]) -> Gather:
        aJ, alo, aup = at

        def gather(v: Sequence[Any], o: int, args: list[Any], scal: np.ndarray, n: int) -> bool:
            J, lo, up = v[o], v[o + 1], v[o + 2]
            if not (_floats(J, 2) and _floats(lo, 1) and _floats(up, 1)):
                return False
            args[aJ], args[alo], args[aup] = J, lo, up
            return True

        return gather

    return RowOp(rk.LEVEL, "mvv", (J, lower, upper), bind)
