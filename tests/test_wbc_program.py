"""The whole-body controller's compiled problem writer (sotpy.solvers.wbc.program) and the
QP kernel's rows of the identity, against the Python writers they replace and against
Pinocchio: the same buffers, bit for bit or to rounding, on random states and structures.
"""

from __future__ import annotations

import example_robot_data as erd
import numpy as np
import pinocchio as pin
import pytest

from sotpy.solvers.wbc import (
    BilateralContactSpec,
    CartesianAccelerationTask,
    CoMAccelerationTask,
    ContactSpec,
    JointAccelerationTask,
    JointPositionLimit,
    JointTorqueLimit,
    JointVelocityLimit,
    TorqueTask,
    WholeBodyController,
    WrenchTask,
    _kernels,
)
from sotpy.solvers.wbc._kernels import CONSTANT, GENERAL, NO_TAU
from sotpy.solvers.wbc.program import owns, row_kinds, unit_columns
from sotpy.tasks import _rowkernels as rk

pytestmark = pytest.mark.skipif(
    rk.write_problem is None or _kernels.solve is None,
    reason="compiled kernels unavailable (numba missing, SOTPY_JIT=0 or not compiled yet)",
)

FEET = ("left_sole_link", "right_sole_link")


@pytest.fixture(scope="module")
def talos():
    return erd.load("talos")


class ScaledHand(CartesianAccelerationTask):
    """A user's task that overrides write() alone: the program must not write it."""

    def write(self, robot, layout, E, f, first) -> None:
        super().write(robot, layout, E, f, first)
        E[:, layout.a] *= 2.0
        f *= 2.0


def _controller(talos, bilateral=False, feedback=True):
    w = WholeBodyController(talos.model)
    contacts = [
        ContactSpec(f, 6, 0.5, 0.2, 0.12, (-0.005, 0.0), 20.0, 0.01, 8, 80.0 if feedback else 0.0)
        for f in FEET
    ]
    if bilateral:
        contacts.append(BilateralContactSpec("arm_left_7_link", "arm_right_7_link"))
    w.setContacts(contacts)
    w.addTask(CoMAccelerationTask("com", 10.0)).setDesired([0.0, 0.2, 0.0])
    w.addTask(CartesianAccelerationTask("hand", "arm_right_7_link", 5.0)).setDesired(
        [0.3, 0.0, 0.2, 0.1, 0.0, 0.0]
    )
    w.addTask(ScaledHand("scaled", "arm_left_7_link", 1.0)).setDesired(np.full(6, 0.1))
    w.addTask(JointAccelerationTask("posture", w.robot.na, 1e-2)).setDesired(
        np.linspace(-1, 1, w.robot.na)
    )
    w.addTask(TorqueTask("torque", w.robot.na, 1e-4)).setDesired(np.ones(w.robot.na))
    w.addTask(WrenchTask("wrench", FEET[0], 6, 1e-3)).setDesired([0, 0, 400, 0, 0, 0])
    w.addConstraint(JointTorqueLimit("tau", w.robot))
    w.addConstraint(JointVelocityLimit("vel", w.robot, 0.05))
    w.addConstraint(JointPositionLimit("pos", w.robot, 0.05))
    w.activateTasksAndConstraints()
    return w


def _states(talos, n, seed):
    rng = np.random.default_rng(seed)
    q0 = talos.q0.copy()
    for _ in range(n):
        q = q0.copy()
        q[7:] += rng.normal(size=talos.model.nq - 7) * 0.05
        q[:3] += rng.normal(size=3) * 0.01
        v = rng.normal(size=talos.model.nv) * 0.3
        yield q, v


def _both(w):
    """The packed problem written by the program, then by the Python writers, at the
    state of the last ``w.robot.update`` (the same tick's structure)."""
    w.problem(False)  # a structure's first tick is written in Python: not compared
    asm = w._assembly
    assert asm.program is not None and asm.program.enabled
    w.problem(False)
    fused = asm.data.copy()
    asm.data[:] = np.nan  # every entry the Python path rewrites must be rewritten
    asm.program.enabled = False
    try:
        w.problem(False)
        w.problem(False)  # the second one is the steady tick of the Python path
    finally:
        asm.program.enabled = True
    return fused, asm.data.copy(), asm


def _settle(w, talos):
    """A few ticks so that every contact has a reference and the cost observed loads."""
    for q, v in _states(talos, 3, 99):
        w.update(q, v, 0.0, 1e-3)


def _assert_feedback_rows(w, talos, seed):
    """At a random state, the first foot's contact rows (the program's: not a
    structure's first tick) have Pinocchio's right-hand side ``-Jdot v - kp
    log6(M_ref^-1 M) - kd nu`` (LOCAL) with its contact state's reference."""
    st = w.contact_states[FEET[0]]
    q, v = next(_states(talos, 1, seed))
    w.robot.update(q, v)
    w.problem(False)
    asm = w._assembly
    m, d = talos.model, w.robot.data
    fid = m.getFrameId(FEET[0])
    kp, kd = st.spec.gains
    rhs = -(
        pin.getFrameAcceleration(m, d, fid, pin.LOCAL).vector
        + kp * pin.log6(st.reference.actInv(d.oMf[fid])).vector
        + kd * pin.getFrameVelocity(m, d, fid, pin.LOCAL).vector
    )
    r = sum(c.count(w.robot, w.layout) for c in w.constraints.values())
    assert np.allclose(asm.lo[r : r + 6], rhs, atol=1e-10)
    assert np.array_equal(asm.lo[r : r + 6], asm.hi[r : r + 6])


@pytest.mark.parametrize("bilateral", [False, True])
def test_the_program_writes_what_the_python_writers_write(talos, bilateral):
    w = _controller(talos, bilateral)
    if bilateral:  # and more tasks than one call of the kernel takes
        links = ("arm_left_4_link", "arm_right_4_link", "torso_2_link", "head_2_link",
                 "leg_left_4_link", "leg_right_4_link")  # fmt: skip
        for i, link in enumerate(links):
            task = w.addTask(CartesianAccelerationTask(f"extra{i}", link, 0.1))
            task.setDesired(np.full(6, 0.01 * i))
            task.activate()
    _settle(w, talos)
    for q, v in _states(talos, 5, 1):
        w.robot.update(q, v)
        fused, python, asm = _both(w)
        # what the Python path leaves NaN it does not write per tick: constant entries
        # (written at the structure's first tick and identical in both)
        keep = np.isfinite(python)
        scale = 1.0 + np.abs(python[keep]).max()
        assert np.allclose(fused[keep], python[keep], rtol=0, atol=1e-12 * scale)
        # the program covers what the Python writers write at each tick, no less: the
        # entries it leaves to them are the constant ones and those of the task it must
        # not write (a subclass overriding write() alone)
        names = [t.name for t in asm.live_tasks]
        assert "scaled" not in [names[i] for i in asm.program.fused]
        assert {"com", "hand", "posture", "torque", "wrench"} <= {
            names[i] for i in asm.program.fused
        }
        assert len(asm.program.calls) > 1 or not bilateral  # a program cut into calls


def test_contacts_ramping_and_inactive(talos):
    """A contact deactivating (its ramp row, by Python) and one inactive (only its
    wrench columns in the dynamics, by the program): the same buffers."""
    w = _controller(talos)
    _settle(w, talos)
    w.contact_states[FEET[1]].setRampDuration(0.5)
    w.contact_states[FEET[1]].deactivate()
    states = list(_states(talos, 4, 2))
    for q, v in states[:2]:
        w.update(q, v, 0.0, 1e-3)  # ramping: a ramp row per tick
        w.robot.update(q, v)
        fused, python, asm = _both(w)
        assert asm.contact_ramps
        keep = np.isfinite(python)
        assert np.allclose(fused[keep], python[keep], rtol=0, atol=1e-10)
    w.contact_states[FEET[1]].setRampDuration(0.0)
    w.update(*states[2], 0.0, 1e-3)
    assert w.contact_states[FEET[1]].state == "inactive"
    w.robot.update(*states[3])
    fused, python, _asm = _both(w)
    keep = np.isfinite(python)
    assert np.allclose(fused[keep], python[keep], rtol=0, atol=1e-10)


def test_the_contact_feedback_matches_pinocchio(talos):
    """The contact rows' right-hand side of the program against Pinocchio directly:
    ``-Jdot v - kp log6(M_ref^-1 M) - kd nu`` (LOCAL), the reference moved away."""
    w = _controller(talos)
    _settle(w, talos)
    st = w.contact_states[FEET[0]]
    st.reference = st.reference * pin.SE3(
        pin.rpy.rpyToMatrix(0.02, -0.03, 0.1), np.array([0.01, -0.02, 0.005])
    )
    _assert_feedback_rows(w, talos, 3)


def test_log6_against_pinocchio():
    rng = np.random.default_rng(4)
    cases = [pin.SE3.Random() for _ in range(200)]
    cases += [pin.SE3(pin.exp3(np.array([np.pi - 1e-7, 0, 0])), np.ones(3))]  # near pi
    cases += [pin.SE3(pin.exp3(rng.normal(size=3) * 1e-9), rng.normal(size=3))]  # tiny
    for M in cases:
        ref = pin.SE3.Random()
        target = ref * M
        got = rk.log6(target.homogeneous, ref.homogeneous)
        want = pin.log6(ref.actInv(target)).vector
        assert np.allclose(got, want, atol=1e-9 * (1 + np.abs(want).max())), (got, want)


def test_refused_arrays_fall_back_to_the_python_writers(talos):
    """A task whose terms() are of the wrong shape: the kernel refuses the tick before
    anything is used, and the Python writers write it (the same buffers)."""

    class Liar(CartesianAccelerationTask):
        def terms(self, robot):
            J, drift = super().terms(robot)
            return J[:5], drift

        def write(self, robot, layout, E, f, first) -> None:
            super().write(robot, layout, E, f, first)

    w = _controller(talos)
    w.addTask(Liar("liar", "arm_left_7_link", 1.0)).activate()
    _settle(w, talos)
    q, v = next(_states(talos, 1, 5))
    w.robot.update(q, v)
    w.problem(False)
    asm = w._assembly
    live = [(t, t.row_weight_vector()) for t in asm.live_tasks]
    assert not asm.program.run(asm.data, live)  # refused
    fused, python, _asm = _both(w)
    keep = np.isfinite(python)
    assert np.array_equal(fused[keep], python[keep])  # both from the Python writers


def test_owns_needs_both_methods_in_the_same_class():
    class OnlyWrite(JointTorqueLimit):
        def write(self, *args) -> None:  # a user's rows: not the identity any more
            super().write(*args)

    assert owns(CartesianAccelerationTask("h", "f"), "terms")
    assert not owns(ScaledHand("s", "f"), "terms")
    assert owns(JointAccelerationTask("p", 3), "unit_rows")
    assert not owns(CoMAccelerationTask("c"), "unit_rows")
    assert not owns(OnlyWrite.__new__(OnlyWrite), "unit_rows")


def test_unit_columns():
    rows = np.array([[0, 1.0, 0], [0, 2.0, 0], [1.0, 1.0, 0], [0, 0, 0], [0, 0, 1.0]])
    assert unit_columns(rows).tolist() == [1, -1, -1, -1, 2]


def test_row_kinds():
    """What the QP kernel may skip in a row: a row of the identity gives its column (if
    asked), a row without torque entries the kind given, any other GENERAL."""
    tau = slice(2, 4)
    rows = np.array([[1.0, 0, 0, 0, 0], [0, 0, 1.0, 0, 0], [0.5, 0, 0, 0, 2.0],
                     [0.5, 0, 0, 3.0, 0]])  # fmt: skip
    assert row_kinds(rows, tau, NO_TAU).tolist() == [0, 2, NO_TAU, GENERAL]
    assert row_kinds(rows, tau, CONSTANT, units=False).tolist() == [
        CONSTANT,
        GENERAL,
        CONSTANT,
        GENERAL,
    ]


def test_constant_rows_are_reduced_once_per_structure(talos):
    """The friction rows (CONSTANT) are mapped to ``y`` at a structure's first call of
    the kernel and kept in the workspace: a later call of the same structure leaves
    them as they are (a poisoned copy stays poisoned), a call for another structure
    with the same workspace writes them again."""
    w = _controller(talos)
    _settle(w, talos)
    asm = w._assembly
    qp = w.weighted_qp
    lay = w.layout
    const = np.flatnonzero(asm.unit[asm.m :] == CONSTANT)
    assert len(const) >= 2 * 15  # the two feet's friction and CoP rows
    ws, views = qp._workspace(lay.nv, lay.na, lay.n, asm.m, asm.mc)
    Cy = views[4]
    good = Cy[const].copy()
    assert np.isfinite(good).all() and np.abs(good).max() > 0
    Cy[const] = np.nan
    qp._kernel(asm.data, ws, lay.nv, lay.na, lay.n, asm.m, asm.mc, 1e-8, False)
    assert np.isnan(Cy[const]).all()  # kept: not this structure's first call
    qp._structure = object()  # another structure, the same sizes and workspace
    qp._kernel(asm.data, ws, lay.nv, lay.na, lay.n, asm.m, asm.mc, 1e-8, False)
    assert np.array_equal(Cy[const], good)


def test_the_qp_kernel_takes_the_rows_of_the_identity_exactly(talos):
    """The compiled QP with the rows of the identity marked and without: the same
    reduced problem (``H, g``, the constraints over ``y``; the solve that follows reads
    only those)."""
    w = _controller(talos)
    _settle(w, talos)
    q, v = next(_states(talos, 1, 6))
    w.robot.update(q, v)
    w.problem(False)
    asm = w._assembly
    assert (asm.unit >= 0).sum() >= w.robot.na * 2  # the posture and the torque limits
    qp = w.weighted_qp
    lay = w.layout
    out = []
    for unit in (asm.unit, np.zeros(0, dtype=np.intp)):
        qp._unit = unit
        ws, views = qp._workspace(lay.nv, lay.na, lay.n, asm.m, asm.mc)
        status, _ok = qp._kernel(asm.data, ws, lay.nv, lay.na, lay.n, asm.m, asm.mc, 1e-8, True)
        assert status == 0
        out.append([x.copy() for x in views[:9]])
    for a, b in zip(*out, strict=True):
        assert np.array_equal(np.isinf(a), np.isinf(b))  # one-sided rows stay so
        fa, fb = a[np.isfinite(b)], b[np.isfinite(b)]
        assert np.allclose(fa, fb, rtol=1e-12, atol=1e-12 * (1 + np.abs(fb).max(initial=0)))


def test_frame_placements_are_computed_when_read(talos):
    """RobotModel.update does not place every frame; a frame read through the model is
    placed at the state of the last update (Pinocchio's framesForwardKinematics)."""
    w = _controller(talos)
    ref = talos.model.createData()
    for q, v in _states(talos, 3, 9):
        w.robot.update(q, v)
        pin.framesForwardKinematics(talos.model, ref, q)
        for name in ("arm_right_7_link", FEET[0], "head_2_link"):
            fid = talos.model.getFrameId(name)
            got = w.robot.frame_placement(fid)
            assert np.allclose(got.homogeneous, ref.oMf[fid].homogeneous, atol=1e-12)


def test_a_subclass_begin_is_called_at_every_tick(talos):
    """The tick skips Activatable.begin/end for an active object without callbacks;
    a subclass's own begin (here: a target that moves) is still called every tick."""

    class Moving(CoMAccelerationTask):
        def begin(self, t, dt):
            self.setDesired([0.0, 0.1 * t, 0.0])
            return super().begin(t, dt)

    w = _controller(talos)
    task = w.addTask(Moving("moving", 1.0))
    task.activate()
    q, v = next(_states(talos, 1, 10))
    for k in range(3):
        w.update(q, v, 0.5 * (k + 1), 1e-3)
        assert task.state == "active" and task.desired[1] == 0.05 * (k + 1)


def test_a_torque_limit_shared_by_two_controllers_reaches_both(talos):
    """New bounds of a constraint added to two controllers reach both problems (the
    write skipped when nothing changed is skipped per buffer)."""
    limit = None
    ws = []
    for _ in range(2):
        w = _controller(talos)
        if limit is None:
            limit = w.constraints["tau"]
        else:
            w.remove("tau")
            w.addConstraint(limit)
        ws.append(w)
    q, v = next(_states(talos, 1, 11))
    for w in ws:
        w.update(q, v, 0.0, 1e-3)
        w.update(q, v, 0.0, 1e-3)
    limit.upper = limit.upper * 0.5  # new bounds, the same kept joints
    for w in ws:
        w.update(q, v, 0.0, 1e-3)
        r = 0  # the torque limit's first row: after the constraints before it
        for con in w.constraints.values():
            if con is limit:
                break
            r += con.count(w.robot, w.layout)
        assert np.array_equal(w._assembly.hi[r : r + len(limit.upper)], limit.upper)


def test_a_first_write_that_fails_is_made_again(talos):
    """A task whose write raises at a structure's first tick: the error reaches the
    caller, and the next tick builds the buffers again (their constant entries, the
    friction rows, are not left unwritten)."""

    class Flaky(JointAccelerationTask):
        fail = True

        def write(self, robot, layout, E, f, first) -> None:
            if self.fail:
                raise RuntimeError("flaky")
            super().write(robot, layout, E, f, first)

    w = _controller(talos)
    _settle(w, talos)
    flaky = w.addTask(Flaky("flaky", w.robot.na, 1e-3))
    flaky.state, flaky.ramp = "active", 1.0  # active at once: no ramp, no transition
    q, v = next(_states(talos, 1, 12))
    w.robot.update(q, v)
    with pytest.raises(RuntimeError, match="flaky"):
        w.problem(False)  # the task's first tick: a new structure
    assert w._assembly is None
    flaky.fail = False
    w.problem(False)  # the same structure as the failed tick's
    w.problem(False)
    asm = w._assembly
    const = np.flatnonzero(asm.unit[asm.m :] == CONSTANT)
    assert len(const) and np.abs(asm.C[const]).sum(axis=1).min() > 0  # friction rows there


def test_a_reference_moved_in_place_reaches_the_rows(talos):
    """The contact feedback's reference changed in place (its translation): the next
    tick's contact rows use it, as Pinocchio computes them."""
    w = _controller(talos)
    _settle(w, talos)
    st = w.contact_states[FEET[0]]
    st.reference.translation[2] += 0.01
    _assert_feedback_rows(w, talos, 13)
