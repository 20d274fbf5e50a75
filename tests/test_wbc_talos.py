"""Example 2 (Talos standing in torque mode, CoM over one foot, hand reaching) and
example 3 (the activation life cycle printed), checked from the simulation's own data."""

from __future__ import annotations

import math

import example_robot_data as erd
import numpy as np
import pinocchio as pin
import pytest

from sotpy.demos.torque import run_callbacks, run_talos_torque

SOLE = (0.205, 0.122, (-0.005, 0.0))  # Talos' soles (docs/robots.md): length, width, centre
MU = 0.5  # the controller's friction coefficient (the floor's: Floor().friction, 0.8)
MARGIN = 0.01  # the controller's CoP margin (m)
RATE_TIME = 0.1  # the documented torque rate bound: effort limit per 0.1 s (torque-control.md)


def _sole_centre(frame: str) -> np.ndarray:
    """The sole's centre in half-sitting with the ankle rolls at 0 (the demo's start)."""
    r = erd.load("talos")
    q = r.q0.copy()
    for j in ("leg_left_6_joint", "leg_right_6_joint"):
        q[r.model.joints[r.model.getJointId(j)].idx_q] = 0.0
    data = r.model.createData()
    pin.framesForwardKinematics(r.model, data, q)
    return data.oMf[r.model.getFrameId(frame)].act(np.array([*SOLE[2], 0.0]))


def _check_talos(out: dict, side: str, floor: bool = True) -> None:
    """The issue's checks, recomputed here from the run's raw arrays: the sole
    placements (Pinocchio, from the device's state), the simulator's own contact
    wrenches and corner forces, the torques sent, the model's effort limits."""
    assert out["solution_found"]
    motion = out["sole_motion"]  # per tick and sole: dx, dy, dz (m), rotation (rad)
    assert np.hypot(motion[:, :, 0], motion[:, :, 1]).max() <= 1e-3  # slides <= 1 mm
    assert motion[:, :, 3].max() <= 0.01  # tilts <= 0.01 rad
    w = out["wrenches"]  # the simulator's, in the sole frames
    fz = w[:, :, 2]
    assert np.all(fz > 0.0)  # every contact pushes, at every tick
    if floor:
        assert np.all(out["corner_fz"] > 0.0)  # no corner of a sole lifts
    assert np.all(np.hypot(w[:, :, 0], w[:, :, 1]) <= MU * fz)  # inside the cones
    length, width, off = SOLE
    cop_x = -w[:, :, 4] / fz - off[0]
    cop_y = w[:, :, 3] / fz - off[1]
    margin = np.minimum(length / 2 - np.abs(cop_x), width / 2 - np.abs(cop_y))
    assert margin.min() >= MARGIN / 2  # the CoP inside the sole with margin
    # torque steps during the hand task's activation ramp, against the documented bound
    k0, k1 = out["ramp_ticks"]
    model = erd.load("talos").model
    bound = model.effortLimit[6:] / RATE_TIME * (out["times"][1] - out["times"][0])
    steps = np.abs(np.diff(out["torques"][k0 - 1 : k1 + 1], axis=0))
    assert np.all(steps <= bound * (1 + 1e-9))
    assert np.all(np.abs(out["torques"]) <= model.effortLimit[6:] * (1 + 1e-9))
    # CoM and hand track their references within 1 mm, and end on their goals
    com_err = np.linalg.norm(out["com"][:, :2] - out["com_ref"][:, :2], axis=1)
    assert com_err.max() <= 1e-3 and com_err[-1] <= 1e-3
    hand_err = np.linalg.norm(out["hand"] - out["hand_ref"], axis=1)
    assert np.nanmax(hand_err[k1:]) <= 1e-3 and out["hand_error"] <= 1e-3
    assert abs(out["com"][-1, 2] - out["com"][0, 2]) < 5e-3  # height kept
    # the CoM went over the stance sole's centre, and the weight with it
    centre = _sole_centre(f"{side}_sole_link")
    assert np.allclose(out["com_goal"][:2], centre[:2], atol=1e-9)
    i = 0 if side == "left" else 1
    reach = slice(k1, k1 + 500)
    assert np.linalg.norm(out["com"][reach, :2] - centre[:2], axis=1).max() < 2e-3
    assert np.all(fz[reach, i] / fz[reach].sum(axis=1) > 0.9)
    assert out["ok"]


def test_talos_shifts_com_reaches_and_shifts_back_on_a_floor(tmp_path):
    """The issue's demo on the contact simulator (MuJoCo floor, four corners per sole)."""
    out = run_talos_torque(plot=tmp_path / "talos.png")
    _check_talos(out, "left")
    assert out["contacts"] == "floor"
    # the controller's wrenches are what the floor gave, once the soft floor's forces have
    # built up from zero penetration (29 N apart at the first tick, 2 N after 20 ms)
    assert out["wrench_mismatch"][20:].max() < 2.0
    assert (tmp_path / "talos.png").stat().st_size > 10_000


def test_talos_welded_feet_remain_an_option():
    out = run_talos_torque(duration=1.0, settle=0.1, contacts="welded")
    assert out["contacts"] == "welded" and np.isnan(out["min_point_force"])
    _check_talos(out, "left", floor=False)
    assert out["feet_slide"] < 1e-5  # welded: only the integration's drift
    assert out["max_wrench_mismatch"] < 1e-2


@pytest.mark.soak
@pytest.mark.parametrize(
    "strategy,side,offset,duration",
    [
        ("OneLevelWeighted", "right", (0.15, 0.0, 0.05), 1.5),
        ("MultiLevelWeighted", "left", (0.15, 0.0, 0.05), 1.5),
        # the demo's own motion (a 1 s shift) with the hierarchical strategy: the light
        # foot's wrench was on its cone's edges while the contact cost had a level of its
        # own below the posture (a corner off the floor, the foot slid 1.3 mm)
        ("MultiLevelWeighted", "left", None, 1.0),
    ],
)
def test_talos_soak(strategy, side, offset, duration):
    extra = {} if offset is None else {"hand_offset": offset}
    out = run_talos_torque(duration=duration, settle=1.0, side=side, strategy=strategy, **extra)
    _check_talos(out, side)


def _expected(ramps: dict[str, float], dt: float) -> list[tuple[int, str, str]]:
    """The documented life cycle, rebuilt from docs/torque-control.md: a ramp of T s
    takes max(1, round(T / dt)) ticks, objects in the order they were added."""
    names = list(ramps)
    steps = {n: max(1, round(ramps[n] / dt)) for n in names}
    ev: list[tuple[int, str, str]] = [(0, n, "onActivation") for n in names]
    tick = 0
    left = dict(steps)
    while any(left.values()):
        live = list(names)  # every object is activating or active
        ev += [(tick, n, "onComputeBegin") for n in live]
        for n in live:
            ev.append((tick, n, "onComputeEnd"))
            if left[n]:
                left[n] -= 1
                if not left[n]:
                    ev.append((tick, n, "onActivated"))
        tick += 1
    ev += [(tick, n, "onDeactivation") for n in names]
    left = dict(steps)
    while any(left.values()):
        live = [n for n in names if left[n]]
        ev += [(tick, n, "onComputeBegin") for n in live]
        for n in live:
            ev.append((tick, n, "onComputeEnd"))
            left[n] -= 1
            if not left[n]:
                ev.append((tick, n, "onDeactivated"))
        tick += 1
    return ev


def test_callbacks_print_their_sequence(capsys):
    ramps = {"ee": 0.002, "posture": 0.003, "torque": 0.0}
    lines = run_callbacks(ramps)
    printed = capsys.readouterr().out.splitlines()
    assert printed == lines
    got = []
    for line in printed:
        f = line.split()
        assert math.isclose(float(f[2].removeprefix("t=")), int(f[1]) * 0.001)
        got.append((int(f[1]), f[4], f[5]))
    assert got == _expected(ramps, 0.001)
    # ramps shown: 1/3 steps for the posture, 1 at onActivated, 0 at onDeactivated
    post = [float(line.split()[-1]) for line in printed if " posture  onComputeEnd" in line]
    assert np.allclose(post[:3], [0.33, 0.67, 1.0]) and post[-1] == 0.0
    for line in printed:
        if "onActivated" in line:
            assert line.endswith("ramp 1.00")
        if "onDeactivated" in line:
            assert line.endswith("ramp 0.00")
    quiet = run_callbacks(ramps, compute=False, echo=False, prefix="cb2")
    assert capsys.readouterr().out == ""
    assert [ln for ln in lines if "onCompute" not in ln] == quiet


def test_cli_demos(tmp_path, capsys):
    from sotpy.cli import main

    assert main(["demo", "torque-callbacks", "--no-compute"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split()[4:6] == ["ee", "onActivation"]
    assert out[-1].split()[4:6] == ["posture", "onDeactivated"]
    assert not any("onCompute" in line for line in out)
    png = tmp_path / "talos.png"
    args = ["demo", "talos-torque", "--duration", "1.0", "--settle", "0.1", "--plot", str(png)]
    assert main(args) == 0
    assert "talos-torque OK (floor)" in capsys.readouterr().out
    assert png.stat().st_size > 10_000
    assert main(["demo", "talos-torque", "--side", "up"]) == 2  # usage error
    assert "invalid choice: 'up'" in capsys.readouterr().err
