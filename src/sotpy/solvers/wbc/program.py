r"""The whole-body controller's problem program: one compiled call writes the entries of
a tick's problem that change with the state.

At each tick the controller's problem (:meth:`.solver.WholeBodyController.problem`)
needs the mass matrix, the nonlinear effects, every contact's Jacobian (in the
equations of motion and in its rows), drift and feedback, and every task's Jacobian,
target and weights. Written by the objects' own Python writers (:meth:`.tasks.Task.write`,
:meth:`.constraints.ContactConstraint.write`) that is a few dozen NumPy calls, each a
microsecond or more: as much as the QP itself on Talos. A :class:`ProblemProgram`
(made when the problem's structure changes, with its buffers) lists one operation per
entry block (``WBC_DYNAMICS``: the mass matrix and ``-b``; ``WBC_CONTACT``: a contact's
``-J^T`` in the dynamics and its rows, the pose feedback's ``log6`` computed there;
``WBC_TASK``: a task's ``J``, target and weights; ``WBC_COST``: the wrench cost's
weights from the last loads) and, per tick, takes the arrays from Pinocchio and the
tasks (its *gathers*: no copies) and hands them to one call of
``sotpy.tasks._rowkernels.write_problem``.

Rules that keep it exact:

* only the entries that change are written; the constant ones (friction rows, a
  posture's selection, the torque columns) are written once by the Python writers when
  the buffers are made, which is also what a tick without the program runs;
* a task is in the program only if its class's :meth:`.tasks.Task.terms` says what its
  :meth:`~.tasks.Task.write` computes (the built-in tasks; a subclass that overrides
  ``write`` but not ``terms`` is written by its ``write`` at every tick); the
  constraints', the contact ramps' and the torque rate's bounds stay with their Python
  writers;
* an array of an unexpected shape makes the kernel refuse the tick before anything is
  used (``REFUSED``), and an argument type it was not compiled for
  raises ``TypeError``: the tick is then written by the Python writers (and, for a type,
  every later one too), which raise their own errors.

The tests compare the program's buffers with the Python writers' on random states and
structures (contacts active, ramping and inactive, bilateral, custom tasks).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pinocchio as pin

from ..._jit import refused
from ...tasks import _rowkernels as rk
from ._kernels import GENERAL, data_layout
from .constraints import Constraint
from .model import Layout, RobotModel
from .tasks import Task

__all__ = ["ProblemProgram", "owns", "row_kinds", "unit_columns"]

#: ``gather(args)``: put this tick's arrays at the operation's positions of ``args``
#: (the kernel's ``m0, ..., v0, ...`` arguments, in that order).
Gather = Callable[[list], None]

_LOCAL = pin.LOCAL
_frame_jacobian = pin.getFrameJacobian
_frame_acceleration = pin.getFrameAcceleration
_placement = pin.updateFramePlacement


def owns(obj: object, attr: str) -> bool:
    """Whether ``obj``'s ``attr`` (``terms``, ``unit_rows``) describes its ``write``: the
    first class of its MRO that defines either defines both (and is not the base
    class): a subclass that overrides ``write`` alone is not described."""
    for cls in type(obj).__mro__:
        has_attr, has_write = attr in cls.__dict__, "write" in cls.__dict__
        if has_attr or has_write:
            return has_attr and has_write and cls not in (Task, Constraint)
    return False


def unit_columns(rows: np.ndarray) -> np.ndarray:
    """For each row of ``rows``, the column of its only nonzero entry if that entry is
    1, else -1."""
    nz = rows != 0.0
    one = (nz.sum(axis=1) == 1) & (rows.max(axis=1, initial=0.0) == 1.0)
    return np.where(one, nz.argmax(axis=1), -1)


def row_kinds(rows: np.ndarray, tau: slice, kind: int, units: bool = True) -> np.ndarray:
    """The QP kernel's ``unit`` entries of ``rows`` (see ``_kernels.solve``): with
    ``units``, a row of the identity gives its column; another row without torque
    entries (columns ``tau``) gives ``kind``, and one with them ``GENERAL``."""
    out = np.where(np.any(rows[:, tau] != 0.0, axis=1), GENERAL, kind)
    if units:
        cols = unit_columns(rows)
        out = np.where(cols >= 0, cols, out)
    return out


class _Call:
    """One call of the kernel: its operations and scalars, what its gathers take, and
    the positions of its array arguments still free."""

    def __init__(self) -> None:
        self.code: list[list[int]] = []
        self.scal: list[float] = []
        self.feet: list[tuple] = []  # (frame id, positions of J, drift, H, Hd; state)
        self.tasks: list[tuple] = []  # (live index, task, terms?, J, drift, desired, w)
        self.others: list[Gather] = []
        self.v = -1  # the position of the robot's velocity (feedback), if any
        self.loads = -1  # the position of the last solution's wrenches (the cost), if any
        self.weights: list[int] = []  # where the cost's weight goes in scal
        self.mats = 0
        self.vecs = 0

    def fits(self, mats: int, vecs: int) -> bool:
        return self.mats + mats <= rk.WBC_MATS and self.vecs + vecs <= rk.WBC_VECS

    def mat(self) -> int:
        self.mats += 1
        return self.mats - 1

    def vec(self) -> int:
        """A vector's position in ``args`` (its index in the kernel's ``vecs`` is this
        minus ``MATS``)."""
        self.vecs += 1
        return rk.WBC_MATS + self.vecs - 1


def _v(position: int) -> int:
    """The kernel's index in ``vecs`` of an ``args`` position (-1 stays -1)."""
    return position - rk.WBC_MATS if position >= 0 else -1


class ProblemProgram:
    """The operations of one problem structure (see the module doc).

    Args:
        robot, layout: the controller's model and layout.
        contact_plan: the contact constraint's plan, ``[(spec, state, nf, ramp, slice,
            ContactState)]`` in layout order (``ContactConstraint.structure``), and
            ``contact_row``: its first row in ``C``.
        tasks: ``[(task, first row in E)]``, the live tasks in the order of
            :meth:`run`'s ``live``; those whose :meth:`~.tasks.Task.terms` are their
            own join the program (``fused``: their indices).
        cost: ``(ContactWrenchCost, its contacts, its first row in E)``: the program
            writes its weights (from the loads of the last solution observed).
        sizes: ``(nv, n, m, mc)`` of the buffers.
    """

    def __init__(
        self,
        robot: RobotModel,
        layout: Layout,
        contact_plan: list,
        contact_row: int,
        tasks: list,
        cost: tuple,
        sizes: tuple[int, int, int, int],
    ) -> None:
        self.robot = robot
        self.layout = layout
        self.cost = cost[0]
        self.sizes = sizes
        self.fused: list[int] = []
        self.enabled = rk.write_problem is not None
        calls = [_Call()]
        calls[0].code.append([rk.WBC_DYNAMICS] + [-1] * (rk.WBC_FIELDS - 1))

        def call_for(mats: int, vecs: int, shared: str = "") -> _Call:
            """The call with room for ``mats`` and ``vecs`` more arrays, and for the
            vector ``shared`` (``"v"``, ``"loads"``: one per call) if it has none."""
            need = vecs + int(bool(shared) and getattr(calls[-1], shared) < 0)
            if not calls[-1].fits(mats, need):
                calls.append(_Call())
            call = calls[-1]
            if shared and getattr(call, shared) < 0:
                setattr(call, shared, call.vec())
            return call

        r = contact_row
        for c, state, nf, ramp, sl, st in contact_plan:
            d = c.dim
            if state == "inactive":  # its wrench columns of the dynamics only
                call = call_for(1, 0)
                jm = call.mat()
                call.code.append([rk.WBC_CONTACT, -1, sl.start, d, jm, -1, -1, -1, -1, -1])
                call.others.append(self._jacobian_gather(c, jm))
                r += d
                continue
            fb = st is not None and st.has_feedback
            call = call_for(1 + 2 * fb, 1, "v" if fb else "")  # J, H, Hd; drift; qdot
            jm, iu = call.mat(), call.vec()
            ih, ihd = (call.mat(), call.mat()) if fb else (-1, -1)
            s = len(call.scal) if fb else -1
            if fb:
                call.scal += list(c.gains)
            call.code.append([rk.WBC_CONTACT, r, sl.start, d, jm, ih, ihd, _v(iu),
                              _v(call.v) if fb else -1, s])  # fmt: skip
            if c.bilateral:
                call.others.append(self._bilateral_gather(c, jm, iu))
            else:
                call.feet.append((robot.frame_id(c.frame), jm, iu, ih, ihd, st if fb else None))
            r += d + nf + ramp
        for i, (task, row) in enumerate(tasks):
            if not owns(task, "terms"):
                continue
            J, drift = task.terms(robot)
            nj, nd = int(J is not None), int(drift is not None)
            call = call_for(nj, 2 + nd)
            jm = call.mat() if nj else -1
            iu = call.vec() if nd else -1
            iv, ix = call.vec(), call.vec()
            call.code.append([rk.WBC_TASK, row, -1, task.size, jm, -1, -1, _v(iu), _v(iv), _v(ix)])
            call.tasks.append((i, task, bool(nj or nd), jm, iu, iv, ix))
            self.fused.append(i)
        wrench_cost, contacts, row = cost
        count = max(1, sum(1 for c in layout.contacts if not c.bilateral))
        for c in contacts:
            k = 2 if c.dim == 3 else 5
            call = call_for(0, 0, "loads")
            s = len(call.scal)
            call.weights.append(s)
            call.scal += [wrench_cost.weight, max(c.fmin, 0.02 * robot.weight),
                          robot.weight / count]  # fmt: skip
            fz = layout.f[c.key].start - layout.nv - layout.na + 2
            call.code.append([rk.WBC_COST, row, fz, k, -1, -1, -1, -1, _v(call.loads), s])
            row += k
        self.calls = [
            (np.array(call.code, dtype=np.int64), np.array([*call.scal, 0.0]), call)
            for call in calls
        ]
        self._args = list(rk.WBC_PAD)
        nv, n, m, mc = sizes
        lay = data_layout(nv, layout.na, n, m, mc)
        names = ("A", "c", "E", "f", "w", "C", "lo", "hi")
        self._offsets = np.array([lay[k][0] for k in names], dtype=np.int64)

    def _jacobian_gather(self, c, jm: int) -> Gather:
        robot = self.robot

        def gather(args: list) -> None:
            args[jm] = robot.contact_jacobian(c)

        return gather

    def _bilateral_gather(self, c, jm: int, iu: int) -> Gather:
        robot = self.robot

        def gather(args: list) -> None:
            args[jm] = robot.contact_jacobian(c)
            args[iu] = robot.contact_drift(c)

        return gather

    def run(self, data: np.ndarray, live: list) -> bool:
        """Write this tick's entries into ``data`` (the packed buffers); ``live``: the
        ``(task, row weights)`` of this tick. False if the kernel refused them (the
        caller then writes the tick in Python)."""
        if not self.enabled:
            return False
        nv, n, m, mc = self.sizes
        offs = self._offsets
        robot = self.robot
        model, d = robot.model, robot.data
        args = self._args  # (the last tick's arrays stay referenced until replaced)
        try:
            for code, scal, call in self.calls:
                for fid, jm, iu, ih, ihd, st in call.feet:
                    args[jm] = _frame_jacobian(model, d, fid, _LOCAL)
                    args[iu] = _frame_acceleration(model, d, fid, _LOCAL).vector
                    if st is not None:
                        M = _placement(model, d, fid)
                        args[ih] = M.homogeneous
                        args[ihd] = st.reference_homogeneous(M)
                if call.v >= 0:
                    args[call.v] = robot.v
                for g in call.others:
                    g(args)
                if call.loads >= 0:
                    loads = self.cost.observed(self.layout)
                    if loads is None:
                        return False  # loads known by contact key: the Python writer
                    args[call.loads] = loads
                    for s in call.weights:
                        scal[s] = self.cost.weight
                for i, task, terms, jm, iu, iv, ix in call.tasks:
                    if terms:
                        J, drift = task.terms(robot)
                        if jm >= 0:
                            args[jm] = J
                        if iu >= 0:
                            args[iu] = drift
                    args[iv] = task.desired
                    args[ix] = live[i][1]
                M = d.M  # read last: a view that the Pinocchio calls above leave alone
                if rk.write_problem(data, offs, nv, n, m, mc, code, scal, M, robot.b, *args):
                    return False
        except TypeError as exc:  # an argument type the kernel was not compiled for
            self.enabled = False
            refused("WholeBodyController's problem program", exc)
            return False
        return True
