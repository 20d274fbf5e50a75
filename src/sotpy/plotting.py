r"""Figures: a :class:`~sotpy.graph.tracer.Tracer` recording, and the demos' runs.

The demos' figures (:func:`plot_reach`, :func:`plot_robot_tour`,
:func:`plot_panda_torque`, :func:`plot_talos_torque`) take the dict a demo returns and
draw what its checks are about; each has a title, a legend on every axis, units on
every axis (an axis holds metres or radians, never both) and its limits or tolerances
drawn as labelled lines. They are what ``sotpy demo ... --plot PATH`` saves.

A recording of any graph: :func:`plot_tracer`::

    tracer = Tracer("tracer")
    tracer.add(ctrl.torque, "torque"); tracer.add(servo.error, "error")
    tracer.add(ctrl.ramps, "ramps"); tracer.setTimeStep(0.001); tracer.start()
    device.after.addSignal(tracer.trigger)
    ...                                                   # run
    plot_tracer(tracer, {"torques (N m)": ["torque"],
                         "hand error (m)": ["error[0:3]"],
                         "activation ramps": ["ramps"]}, "run.png")

The recording is a ``Tracer`` (its :meth:`~sotpy.graph.tracer.Tracer.data`), the path of
the ``.npz`` its ``dump`` wrote, or a mapping of the same form (``"time"`` (n,), one
``(n, width)`` array per column). Each group is one subplot, sharing the time axis
(``time``: seconds if the tracer had ``setTimeStep``, ticks otherwise); a series is a
column label (every component), ``"label[i]"`` (one component) or ``"label[i:j]"``
(components ``i`` to ``j - 1``); the legend names each line ``label[i]`` (``label``
alone for a one-component column). The figure is a :class:`matplotlib.figure.Figure`
built without pyplot (no global state, nothing to close); it is returned so that its
lines can be inspected.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SotpyError

__all__ = [
    "plot_panda_torque",
    "plot_reach",
    "plot_robot_tour",
    "plot_talos_torque",
    "plot_tracer",
    "plot_walk",
    "recording",
]

_SERIES = re.compile(r"^(?P<label>.+?)(\[(?P<i>-?\d+)(:(?P<j>-?\d*))?\])?$")


def recording(source: Any) -> dict[str, np.ndarray]:
    """The recording of ``source`` (a Tracer, an ``.npz`` path or a mapping) as
    ``{"time": (n,), label: (n, width), ...}``."""
    if hasattr(source, "data") and callable(source.data):
        data = dict(source.data())
    elif isinstance(source, (str, Path)):
        p = Path(source)
        if p.suffix != ".npz" or not p.is_file():
            raise SotpyError(f"plot_tracer: {str(p)!r} is not an .npz file written by Tracer.dump")
        with np.load(p) as z:
            data = {k: z[k] for k in z.files}
    elif isinstance(source, Mapping):
        data = dict(source)
    else:
        what = type(source).__name__
        raise SotpyError(f"plot_tracer: expected a Tracer, an .npz path or a mapping, got {what}")
    if "time" not in data:
        raise SotpyError("plot_tracer: the recording has no 'time' column")
    out = {"time": np.asarray(data["time"], dtype=float).ravel()}
    for k, v in data.items():
        if k in ("time", "tick"):
            continue
        arr = np.asarray(v, dtype=float)
        out[k] = arr.reshape(len(arr), -1) if arr.ndim != 2 else arr
    return out


def _series(data: dict[str, np.ndarray], spec: str) -> list[tuple[str, np.ndarray]]:
    """``[(legend, y)]`` of one series spec (see the module doc)."""
    if spec in data:  # a label that itself ends with [..] wins
        label, i, j = spec, None, None
    else:
        m = _SERIES.match(spec)
        label = m.group("label") if m else spec
        i = m.group("i") if m else None
        j = m.group("j") if m else None
    if label not in data or label == "time":
        cols = [k for k in data if k != "time"]
        raise SotpyError(f"plot_tracer: no column {label!r} in the recording (columns: {cols})")
    arr = data[label]
    width = arr.shape[1]
    if i is None:
        idx = list(range(width))
    elif j is None:
        k = int(i)
        if not -width <= k < width:
            raise SotpyError(
                f"plot_tracer: {spec!r}: component {k} out of range, {label!r} has {width}"
            )
        idx = [k % width]
    else:
        idx = list(range(width))[slice(int(i), int(j) if j else None)]
        if not idx:
            raise SotpyError(f"plot_tracer: {spec!r} selects no component of {label!r} ({width})")
    if width == 1:
        return [(label, arr[:, 0])]
    return [(f"{label}[{k}]", arr[:, k]) for k in idx]


def plot_tracer(
    source: Any,
    groups: Mapping[str, Sequence[str]] | None = None,
    path: str | Path | None = None,
    title: str | None = None,
    xlabel: str | None = None,
    dpi: int = 100,
) -> Any:
    """Plot a recording, one subplot per group, and save it as PNG at ``path``.

    Args:
        source: a ``Tracer``, the path of its ``.npz`` dump, or a mapping like
            ``Tracer.data()``.
        groups: subplot title (used as the y label) -> series specs (``"label"``,
            ``"label[i]"``, ``"label[i:j]"``); default: one subplot per column.
        path: where to save the PNG (None: not saved).
        title: the figure's title.
        xlabel: the time axis' label (default ``"time (s)"`` if the recording has a
            ``tick`` column, i.e. the tracer had a time step, else ``"tick"``).
        dpi: resolution of the PNG.

    Returns:
        The ``matplotlib.figure.Figure``: ``fig.axes[g].lines[s]`` is the ``s``-th line
        of group ``g``, x the time, y the recorded values.

    Raises:
        SotpyError: an unknown column or component, an empty recording or group.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    has_tick = (
        hasattr(source, "data")
        and callable(source.data)
        and getattr(source, "_timeStep", None) is not None
    ) or (isinstance(source, Mapping) and "tick" in source)
    if isinstance(source, (str, Path)) and Path(source).is_file():
        with np.load(source) as z:
            has_tick = "tick" in z.files
    data = recording(source)
    t = data["time"]
    if len(t) == 0:
        raise SotpyError("plot_tracer: the recording is empty (no row recorded)")
    if groups is None:
        groups = {k: [k] for k in data if k != "time"}
    if not groups:
        raise SotpyError("plot_tracer: nothing to plot (no group, no column)")
    fig = Figure(figsize=(8, 2.6 * len(groups)), dpi=dpi)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (name, specs) in zip(axes, groups.items(), strict=True):
        if isinstance(specs, str):
            specs = [specs]
        if not specs:
            raise SotpyError(f"plot_tracer: the group {name!r} has no series")
        for spec in specs:
            for legend, y in _series(data, spec):
                ax.plot(t, y, label=legend)
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
        if len(ax.lines) <= 12:
            ax.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel(xlabel or ("time (s)" if has_tick else "tick"))
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, format="png")
    return fig


# -- the demos' figures ------------------------------------------------------------------
def _figure(width: float, height: float, rows: int, cols: int = 1, **kwargs: Any) -> Any:
    """A pyplot-free figure (the user's backend and pyplot's state are left alone) and
    its axes; a clear error when matplotlib is missing."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise SotpyError(
            "cannot plot: matplotlib is not installed (pip install 'sotpy[plot]')"
        ) from None
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False, **kwargs)
    return fig, axes


def _save(fig: Any, path: str | Path | None, dpi: int = 100) -> None:
    if path is None:
        return
    p = Path(path)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(p, dpi=dpi, format="png")
    except OSError as exc:
        raise SotpyError(f"cannot save the plot {str(p)!r}: {exc}") from None


def _closed(vertices: np.ndarray) -> np.ndarray:
    return np.vstack((vertices, vertices[:1]))


def plot_reach(result: Mapping[str, Any], path: str | Path | None = None) -> Any:
    """The reaching demo's run (the result of ``sotpy.demos.reach.run_reach``), saved as
    PNG at ``path`` if given; returns the ``matplotlib.figure.Figure``.

    Three axes: distances (m, log scale: the wrist to its target with the reach
    tolerance, the soles' drift with the feet's tolerance), angles (rad, log scale: the
    posture error, the soles' rotation, the couplings' residual, with the feet's
    tolerance), and the CoM's ground projection in the support polygon and the polygon
    shrunk by the margin (m), with the start and the end marked.
    """
    fig, axes = _figure(13.0, 4.6, 1, 3, width_ratios=(1.0, 1.0, 0.9))
    ax_m, ax_rad, ax_com = axes[0]
    t = result["time"]
    tol = result["tolerances"]
    tiny = 1e-16
    drift = result["sole_drift"]
    sole_m = np.max([d[:, 0] for d in drift.values()], axis=0)
    sole_rad = np.max([d[:, 1] for d in drift.values()], axis=0)
    ax_m.semilogy(t, np.maximum(result["errors"]["wrist"], tiny), label="wrist to target")
    ax_m.semilogy(t, np.maximum(sole_m, tiny), label="sole drift (largest)")
    ax_m.axhline(
        tol["wrist"], color="C0", ls="--", lw=0.9, label=f"reach tolerance {tol['wrist']:g} m"
    )
    ax_m.axhline(
        tol["feet"], color="C1", ls="--", lw=0.9, label=f"feet tolerance {tol['feet']:g} m"
    )
    ax_m.set_ylabel("distance [m]")
    ax_m.set_title("distances")
    ax_rad.semilogy(
        t, np.maximum(result["errors"]["posture"], tiny), color="C2", label="posture |e|"
    )
    ax_rad.semilogy(t, np.maximum(sole_rad, tiny), color="C1", label="sole rotation (largest)")
    if result["errors"].get("couplings") is not None:
        ax_rad.semilogy(
            t,
            np.maximum(result["errors"]["couplings"], tiny),
            color="C4",
            label="coupling residual",
        )
    ax_rad.axhline(
        tol["feet"], color="C1", ls="--", lw=0.9, label=f"feet tolerance {tol['feet']:g} rad"
    )
    ax_rad.set_ylabel("angle [rad]")
    ax_rad.set_title("angles")
    for ax in (ax_m, ax_rad):
        ax.set_xlabel("time [s]")
        ax.set_ylim(1e-12, None)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(loc="lower left", fontsize=8)
    ax_com.plot(*_closed(result["polygon"]).T, "k-", label="support polygon")
    inner = result.get("polygon_inner")
    if inner is not None:
        ax_com.plot(*_closed(inner).T, "k--", lw=0.8, label=f"margin {result['margin']:g} m")
    c = result["com"]
    ax_com.plot(c[:, 0], c[:, 1], "C0-", label="CoM projection")
    ax_com.plot(c[0, 0], c[0, 1], "C0o", ms=5, label="start")
    ax_com.plot(c[-1, 0], c[-1, 1], "C0s", ms=5, label="end")
    ax_com.set_aspect("equal", adjustable="datalim")
    ax_com.set_xlabel("x [m]")
    ax_com.set_ylabel("y [m]")
    ax_com.grid(True, alpha=0.3)
    ax_com.legend(loc="upper right", fontsize=8)
    ax_com.set_title("CoM over the support polygon")
    verdict = "OK" if result["ok"] else "FAILED"
    fig.suptitle(
        f"{result['robot']} reaching with its right wrist, feet fixed, CoM inside: {verdict}"
    )
    _save(fig, path)
    return fig


def plot_robot_tour(result: Mapping[str, Any], path: str | Path | None = None) -> Any:
    """The robot tour's run (the result of ``sotpy.demos.robot_tour.run_robot_tour``),
    saved as PNG at ``path`` if given; returns the ``matplotlib.figure.Figure``.

    Three axes: the followed op point's position (m, world), the CoM (m, world), and
    each swinging joint's position as a fraction of its range (0 and 1: its position
    limits, drawn and labelled).
    """
    fig, axes = _figure(9.0, 9.0, 3, 1, sharex=True)
    ax_w, ax_c, ax_j = axes[:, 0]
    path_ = result["path"]
    t = path_[:, 0]
    for i, axis in enumerate("xyz"):
        ax_w.plot(t, path_[:, 1 + i], label=f"{result['wrist']} {axis}")
        ax_c.plot(t, path_[:, 4 + i], label=f"CoM {axis}")
    ax_w.set_ylabel("position [m]")
    ax_w.set_title(f"{result['wrist']} (world)")
    ax_c.set_ylabel("position [m]")
    ax_c.set_title("centre of mass (world)")
    limits = result["limits"]
    q = result["q"]
    span = limits["upper"] - limits["lower"]
    for name, iq, lo, width in zip(
        limits["joints"], limits["index"], limits["lower"], span, strict=True
    ):
        ax_j.plot(t, (q[:, iq] - lo) / width, lw=0.9, label=name)
    ax_j.axhline(0.0, color="k", ls="--", lw=1.0, label="position limits")
    ax_j.axhline(1.0, color="k", ls="--", lw=1.0)
    ax_j.set_ylim(-0.05, 1.05)
    ax_j.set_ylabel("fraction of the joint's range [-]")
    ax_j.set_title("swinging joints, between their limits")
    ax_j.set_xlabel("time [s]")
    for ax in (ax_w, ax_c, ax_j):
        ax.grid(True, alpha=0.3)
    ax_w.legend(loc="upper right", fontsize=8)
    ax_c.legend(loc="upper right", fontsize=8)
    ax_j.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=7, ncols=2)
    verdict = "OK" if result["ok"] else "FAILED"
    fig.suptitle(f"{result['robot']} tour: arms and head swing, feet still: {verdict}")
    _save(fig, path)
    return fig


def plot_panda_torque(out: Mapping[str, Any], path: str | Path | None = None) -> Any:
    """The Panda torque demo's run (``sotpy.demos.torque.run_panda_torque``), saved
    as PNG at ``path`` if given; returns the ``matplotlib.figure.Figure``.

    Three axes: each joint's torque (N m), each torque as a fraction of its limit with
    the limits at -1 and 1, and the hand's distance to its reference (mm) with the
    demo's success tolerance on the final error.
    """
    fig, axes = _figure(9.0, 9.0, 3, 1, sharex=True)
    ax_tau, ax_ratio, ax_err = axes[:, 0]
    t, tau = out["times"], out["torques"]
    names = out.get("joint_names") or [f"joint {i}" for i in range(tau.shape[1])]
    limits = np.asarray(out["torque_limits"], dtype=float)
    for i, name in enumerate(names):
        ax_tau.plot(t, tau[:, i], color=f"C{i % 10}", lw=0.9, label=name)
        ax_ratio.plot(t, tau[:, i] / limits[i], color=f"C{i % 10}", lw=0.9, label=name)
    ax_ratio.axhline(1.0, color="k", ls="--", lw=1.0, label="torque limits")
    ax_ratio.axhline(-1.0, color="k", ls="--", lw=1.0)
    ax_tau.set_ylabel("torque [N m]")
    ax_tau.set_title("joint torques")
    ax_ratio.set_ylabel("torque / limit [-]")
    ax_ratio.set_title("torques against their limits")
    ax_err.plot(t, 1e3 * out["errors"], "C0", label="hand to its reference")
    tol = out.get("tolerance", 1e-3)
    ax_err.axhline(
        1e3 * tol, color="k", ls="--", lw=1.0, label=f"final-error goal {1e3 * tol:g} mm"
    )
    ax_err.set_ylabel("tracking error [mm]")
    ax_err.set_title("hand position error")
    ax_err.set_xlabel("time [s]")
    for ax in (ax_tau, ax_ratio, ax_err):
        ax.grid(True, alpha=0.3)
    ax_tau.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=7)
    ax_ratio.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=7)
    ax_err.legend(loc="upper right", fontsize=8)
    fig.suptitle("Panda, torque control: the hand follows a minimum-jerk move")
    _save(fig, path)
    return fig


def plot_talos_torque(out: Mapping[str, Any], path: str | Path | None = None) -> Any:
    """The Talos torque demo's run (``sotpy.demos.torque.run_talos_torque``), saved
    as PNG at ``path`` if given; returns the ``matplotlib.figure.Figure``.

    Four axes: each sole's normal and tangential contact force (N, sole frame, the
    simulator's), each CoP in its sole (mm, sole frame, with the sole's edges and the
    controller's CoP bound inside its margin as limits), the torques against their
    limits (the largest ``|tau| / limit`` of each joint group, the limit at 1), and the
    CoM's displacement from its start (mm, world) with the shift's goal on each axis.
    """
    fig, axes = _figure(9.0, 12.0, 4, 1, sharex=True)
    ax_f, ax_cop, ax_tau, ax_com = axes[:, 0]
    t, w = out["times"], out["wrenches"]
    soles = out.get("soles")
    for i, side in enumerate(("left", "right")):
        ax_f.plot(t, w[:, i, 2], color=f"C{2 * i}", label=f"{side} f_z (normal)")
        ax_f.plot(
            t, np.hypot(w[:, i, 0], w[:, i, 1]), "--", color=f"C{2 * i}", label=f"{side} |f_xy|"
        )
        off = soles[i]["offset"] if soles else (0.0, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            cop_x, cop_y = -w[:, i, 4] / w[:, i, 2] - off[0], w[:, i, 3] / w[:, i, 2] - off[1]
        ax_cop.plot(t, 1e3 * cop_x, color=f"C{2 * i}", label=f"{side} CoP x")
        ax_cop.plot(t, 1e3 * cop_y, ":", color=f"C{2 * i}", label=f"{side} CoP y")
    if soles:
        length, width = soles[0]["length"], soles[0]["width"]
        ax_cop.axhline(
            1e3 * length / 2,
            color="k",
            ls="--",
            lw=0.9,
            label=f"sole edges x: ±{500 * length:.0f} mm",
        )
        ax_cop.axhline(-1e3 * length / 2, color="k", ls="--", lw=0.9)
        ax_cop.axhline(
            1e3 * width / 2,
            color="grey",
            ls="-.",
            lw=0.9,
            label=f"sole edges y: ±{500 * width:.0f} mm",
        )
        ax_cop.axhline(-1e3 * width / 2, color="grey", ls="-.", lw=0.9)
        margin = out.get("sole_margin")
        if margin:
            bound = 1e3 * (width / 2 - margin)
            ax_cop.axhline(
                bound, color="r", ls=":", lw=0.9, label=f"CoP bound y (margin {1e3 * margin:g} mm)"
            )
            ax_cop.axhline(-bound, color="r", ls=":", lw=0.9)
    ax_f.set_ylabel("contact force [N]")
    ax_f.set_title("contact forces (sole frames)")
    ax_cop.set_ylabel("CoP [mm]")
    ax_cop.set_title("centres of pressure in the soles (from each sole's centre)")
    tau = out.get("torques")
    limits = out.get("torque_limits")
    if tau is not None and limits is not None:
        names = out.get("joint_names") or [f"joint {k}" for k in range(tau.shape[1])]
        ratio = np.abs(tau) / np.asarray(limits, dtype=float)
        groups: dict[str, list[int]] = {}
        for k, name in enumerate(names):
            group = name.split("_")[0] if "_" in name else name
            groups.setdefault(group, []).append(k)
        for j, (group, idx) in enumerate(groups.items()):
            ax_tau.plot(
                t, ratio[:, idx].max(axis=1), color=f"C{j}", lw=0.9, label=f"{group} joints"
            )
        ax_tau.axhline(1.0, color="k", ls="--", lw=1.0, label="torque limits")
    ax_tau.set_ylabel("max |torque| / limit [-]")
    ax_tau.set_title("torques against their limits")
    com, goal = out["com"], out["com_goal"]
    for j, axis in enumerate("xyz"):
        ax_com.plot(t, 1e3 * (com[:, j] - com[0, j]), color=f"C{j}", label=f"CoM {axis}")
        ax_com.axhline(
            1e3 * (goal[j] - com[0, j]), color=f"C{j}", ls=":", lw=1.0, label=f"goal {axis}"
        )
    ax_com.set_ylabel("CoM - start [mm]")
    ax_com.set_title("centre of mass (world)")
    ax_com.set_xlabel("time [s]")
    for ax in (ax_f, ax_cop, ax_tau, ax_com):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5), fontsize=7)
    side = out.get("side", "")
    over = f" over the {side} foot" if side else ""
    where = {"floor": " on a floor", "welded": ", feet welded"}.get(out.get("contacts", ""), "")
    fig.suptitle(f"Talos{where}, torque control: CoM{over}, right hand reach, CoM back")
    _save(fig, path)
    return fig


def plot_walk(
    result: Mapping[str, Any], plan: Any, path: str | Path | None = None, title: str = "walk"
) -> Any:
    """A walk's run (the result of ``sotpy.demos.walk.run_walk`` and the generator's
    :class:`~sotpy.walking.plan.StepPlan`), saved as PNG at ``path`` if given; returns
    the ``matplotlib.figure.Figure``.

    Top: the top view (m): the planned footprints (soles outlined, left blue, right
    red), the ZMP reference, the multibody ZMP computed from the motion, the CoM.
    Bottom: the multibody ZMP's margin to the support polygon of the feet on the ground
    (mm, positive inside) and its distance to the cart-table ZMP (mm), against time.
    """
    fig, axes = _figure(13.0, 8.0, 2, 1, height_ratios=(1.2, 1.0))
    top, low = axes[0][0], axes[1][0]
    t = np.asarray(result["t"])
    m = result["motion"]
    rows = [plan.initial["left"], plan.initial["right"], *plan.steps]
    corners = plan.sole.corners()
    for f in rows:
        poly = _closed(f.point(corners))
        top.plot(poly[:, 0], poly[:, 1], color="C0" if f.side == "left" else "C3", lw=0.8)
    zref = result["zmp_reference"]
    top.plot(zref[:, 0], zref[:, 1], color="0.4", lw=0.8, label="ZMP reference")
    top.plot(m["zmp"][:, 0], m["zmp"][:, 1], color="C2", lw=0.6, label="multibody ZMP")
    top.plot(m["com"][:, 0], m["com"][:, 1], color="k", lw=1.2, label="CoM")
    top.set_aspect("equal")
    top.set_xlabel("x [m]")
    top.set_ylabel("y [m]")
    top.set_title(f"{title}: top view (soles as planned; left blue, right red)")
    top.legend(loc="upper left", fontsize=8)
    low.plot(t, result["margin_series"] * 1e3, color="C2", lw=0.8, label="ZMP margin")
    dz = np.linalg.norm(m["zmp"] - result["cart_zmp"], axis=1) * 1e3
    low.plot(t, dz, color="C1", lw=0.6, label="|multibody - cart-table ZMP|")
    low.axhline(10.0, color="C2", ls="--", lw=0.9, label="margin target 10 mm")
    low.axhline(0.0, color="k", lw=0.6)
    low.set_xlabel("t [s]")
    low.set_ylabel("[mm]")
    low.set_title(
        "the multibody ZMP (from the motion) in the support polygon of the feet on the ground"
    )
    low.legend(loc="upper right", fontsize=8)
    _save(fig, path)
    return fig
