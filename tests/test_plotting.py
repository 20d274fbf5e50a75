"""sotpy.plotting.plot_tracer: a Tracer recording of the torque controller to PNG, the
figure's lines checked against the recording."""

from __future__ import annotations

import numpy as np
import pytest

from sotpy.dynamics import load_robot
from sotpy.errors import SotpyError
from sotpy.graph import Tracer, plug
from sotpy.plotting import plot_tracer
from sotpy.solvers.controller import Controller, PoseServo

PNG = b"\x89PNG\r\n\x1a\n"


def _run(ticks: int = 12, dt: float = 0.001) -> tuple[Tracer, Controller]:
    robot = load_robot("panda")
    ctrl = Controller("plotCtrl", robot.dynamic)
    ctrl.addCartesianTask("ee", "panda_hand_tcp", 1.0, 0)
    ctrl.addJointTask("posture", 1e-3, 0)
    ctrl.addTorqueLimits("tau")
    ctrl.setRampDuration("ee", 0.005)
    servo = PoseServo("plotServo")
    plug(ctrl.eePose, servo.position)
    plug(ctrl.eeVelocity, servo.velocity)
    start = ctrl.eePose.value
    goal = start.copy()
    goal.translation = goal.translation + np.array([0.05, 0.0, 0.0])
    servo.reference.value = goal
    plug(servo.desiredAcceleration, ctrl.ee)
    ctrl.activateTasksAndConstraints()
    robot.device.setControlType("torque")
    plug(ctrl.torque, robot.device.control)
    tracer = Tracer("plotTracer")
    tracer.add(ctrl.torque, "torque")
    tracer.add(servo.error, "error")
    tracer.add(ctrl.ramps, "ramps")
    tracer.setTimeStep(dt)
    tracer.start()
    robot.device.before.addSignal(tracer.trigger)  # records the tick's control
    for _ in range(ticks):
        robot.device.increment(dt)
    return tracer, ctrl


def test_plot_tracer_lines_match_the_recording(tmp_path):
    tracer, ctrl = _run()
    data = tracer.data()
    assert len(data["time"]) == 12
    groups = {
        "torque (N m)": ["torque"],
        "hand error (m)": ["error[0:3]", "error[5]"],
        "ramps": ["ramps"],
    }
    fig = plot_tracer(tracer, groups, tmp_path / "run.png", title="panda")
    raw = (tmp_path / "run.png").read_bytes()
    assert raw[:8] == PNG and len(raw) > 10_000
    ax_tau, ax_err, ax_ramp = fig.axes
    assert [ax.get_ylabel() for ax in fig.axes] == list(groups)
    assert ax_ramp.get_xlabel() == "time (s)"
    assert len(ax_tau.lines) == 9
    for k, line in enumerate(ax_tau.lines):
        assert line.get_label() == f"torque[{k}]"
        assert np.array_equal(line.get_xdata(), 0.001 * np.arange(12))
        assert np.array_equal(line.get_ydata(), data["torque"][:, k])
    assert [ln.get_label() for ln in ax_err.lines] == [f"error[{k}]" for k in (0, 1, 2, 5)]
    for line, k in zip(ax_err.lines, (0, 1, 2, 5), strict=True):
        assert np.array_equal(line.get_ydata(), data["error"][:, k])
    # the hand error starts at the 5 cm step and shrinks
    assert np.isclose(data["error"][0, 0], -0.05) and data["error"][-1, 0] > -0.05
    # the ramps: ee in 5 ticks (0.2 steps), posture and tau in one tick
    names = ctrl.rampNames()
    assert names == ["ee", "posture", "tau"]
    ee = ax_ramp.lines[0].get_ydata()
    assert np.allclose(ee[:6], [0.2, 0.4, 0.6, 0.8, 1.0, 1.0])
    assert np.all(ax_ramp.lines[1].get_ydata() == 1.0)


def test_plot_tracer_from_npz_and_defaults(tmp_path):
    tracer, _ctrl = _run(ticks=5)
    npz = tracer.dump(str(tmp_path / "run.npz"))
    fig = plot_tracer(npz, path=tmp_path / "all.png")
    assert (tmp_path / "all.png").read_bytes()[:8] == PNG
    assert [ax.get_ylabel() for ax in fig.axes] == ["torque", "error", "ramps"]
    assert np.array_equal(fig.axes[1].lines[3].get_ydata(), tracer.data()["error"][:, 3])
    assert fig.axes[-1].get_xlabel() == "time (s)"
    fig2 = plot_tracer({"time": np.arange(3), "x": np.array([1.0, 2.0, 4.0])}, {"x": ["x"]})
    assert fig2.axes[0].lines[0].get_label() == "x"
    assert fig2.axes[0].get_xlabel() == "tick"
    assert np.array_equal(fig2.axes[0].lines[0].get_ydata(), [1.0, 2.0, 4.0])


def test_plot_tracer_bad_input(tmp_path):
    tracer, _ctrl = _run(ticks=2)
    with pytest.raises(SotpyError, match=r"no column 'nope'.*torque"):
        plot_tracer(tracer, {"x": ["nope"]})
    with pytest.raises(SotpyError, match="out of range"):
        plot_tracer(tracer, {"x": ["torque[9]"]})
    with pytest.raises(SotpyError, match="no series"):
        plot_tracer(tracer, {"x": []})
    with pytest.raises(SotpyError, match="empty"):
        plot_tracer({"time": np.zeros(0), "x": np.zeros((0, 1))})
    with pytest.raises(SotpyError, match="npz"):
        plot_tracer(tmp_path / "missing.npz")


# -- the torque demos' figures -----------------------------------------------------------
def test_panda_torque_figure_names_each_joint_and_its_limits(figure_check, tmp_path):
    from sotpy.demos.torque import run_panda_torque
    from sotpy.plotting import plot_panda_torque

    out = run_panda_torque(duration=0.1, settle=0.02, plot=tmp_path / "panda.png")
    assert (tmp_path / "panda.png").read_bytes()[:8] == PNG
    axes = figure_check(plot_panda_torque(out), "Panda")
    names = [f"panda_joint{i}" for i in range(1, 8)]
    torques, ratios = axes["joint torques"], axes["torques against their limits"]
    assert names <= list(torques["lines"]) and len(torques["lines"]) == out["torques"].shape[1]
    assert torques["ylabel"] == "torque [N m]"
    limits = load_robot("panda").model.effortLimit  # Pinocchio's, independent of the demo
    for k, name in enumerate(names):
        np.testing.assert_allclose(
            ratios["lines"][name].get_ydata(), out["torques"][:, k] / limits[k]
        )
    assert list(ratios["lines"]["torque limits"].get_ydata()) == [1.0, 1.0]
    error = axes["hand position error"]
    assert list(error["lines"]["final-error goal 1 mm"].get_ydata()) == [1.0, 1.0]


def test_talos_torque_figure_labels_the_goals_and_the_soles(figure_check, tmp_path):
    from sotpy.demos.torque import run_talos_torque
    from sotpy.plotting import plot_talos_torque

    out = run_talos_torque(duration=0.7, settle=0.05, plot=tmp_path / "talos.png")
    assert (tmp_path / "talos.png").read_bytes()[:8] == PNG
    axes = figure_check(plot_talos_torque(out), "Talos")
    com = axes["centre of mass (world)"]
    for j, axis in enumerate("xyz"):
        goal = 1e3 * (out["com_goal"][j] - out["com"][0, j])
        assert com["lines"][f"goal {axis}"].get_ydata()[0] == pytest.approx(goal)
    cop = axes["centres of pressure in the soles (from each sole's centre)"]
    foot = load_robot("talos", prefix="t2").feet["left"]
    label = f"sole edges x: ±{500 * foot.length:.0f} mm"
    assert cop["lines"][label].get_ydata()[0] == pytest.approx(500 * foot.length)
    forces = axes["contact forces (sole frames)"]
    np.testing.assert_array_equal(
        forces["lines"]["left f_z (normal)"].get_ydata(), out["wrenches"][:, 0, 2]
    )
