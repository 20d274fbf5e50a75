"""Demos: short stories that run a graph end to end, each a function the ``sotpy demo``
command line and a script of ``examples/`` call.

- :mod:`sotpy.demos.robot_tour`: a humanoid waves its arms and turns its head while
  standing, :func:`~sotpy.demos.robot_tour.run_robot_tour`; ``sotpy demo robot``
  (options :func:`robot_options`, runner :func:`robot_run`, registered in
  ``sotpy.cli.DEMOS``).
- :mod:`sotpy.demos.torque`: the torque-level controller (ORCA-style):
  ``sotpy demo panda-torque`` (:func:`torque_options`, :func:`torque_run`),
  ``sotpy demo talos-torque`` (:func:`torque_talos_options`, :func:`torque_talos_run`),
  ``sotpy demo torque-callbacks`` (:func:`torque_callbacks_options`,
  :func:`torque_callbacks_run`).
- :mod:`sotpy.demos.reach`: the SoT slides' reaching demo on a humanoid (feet fixed,
  CoM over the support polygon, right wrist to a target, half-sitting, joint limits
  hard), :func:`~sotpy.demos.reach.run_reach`; ``sotpy demo talos``, ``romeo``,
  ``nao`` (options :func:`reach_options`, runner :func:`reach_run`).

- :mod:`sotpy.demos.collision`: Talos reaching across its body or past an obstacle
  with a collision level in its ``SOT``; ``sotpy demo talos-collision``
  (:func:`collision_options`, :func:`collision_run`).

The pendulum tutorial (``sotpy demo pendulum``) lives in :mod:`sotpy.tutorial`.

Each demo function is the story itself: the graph built in plain sight, then run; what
it records, checks and prints is :mod:`sotpy.demos.checks`, its figure
:mod:`sotpy.plotting`, and ``--viewer`` is :func:`open_viewer` then :func:`replay` (the
run is computed first, then replayed in the page at real time).

This package only holds the command-line glue, so that building the ``sotpy`` parser
does not import Pinocchio; the demos are imported when they run (``from
sotpy.demos.robot_tour import run_robot_tour``).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from typing import Any

__all__ = [
    "REACH_DEMO_DEFAULTS",
    "REACH_ROBOTS",
    "ROBOT_DEMO_DEFAULTS",
    "TORQUE_STRATEGIES",
    "VIEWER_FRAME",
    "WALK_ROBOTS",
    "collision_options",
    "collision_run",
    "finite_float",
    "non_negative_float",
    "open_viewer",
    "positive_float",
    "reach_options",
    "reach_run",
    "replay",
    "robot_options",
    "robot_run",
    "torque_callbacks_options",
    "torque_callbacks_run",
    "torque_options",
    "torque_run",
    "torque_talos_options",
    "torque_talos_run",
    "ui_options",
    "viewer_options",
    "walk_options",
    "walk_run",
]


#: Seconds of motion between two frames the viewer replays (50 frames/s).
VIEWER_FRAME = 0.02


def open_viewer(robot: Any, prefix: str, emit: Callable[[str], None]) -> Any:
    """A ``RobotViewer`` named ``<prefix>_viewer`` on ``robot``'s models, showing the
    robot where its device is now, with the camera framed on it; prints its address.
    Close it with ``view.close()``. The demo runs without it and sends it the whole
    motion afterwards (:func:`replay`), so the run is not slowed and the motion is seen
    at real time, however long the run took to compute."""
    from ..viewer import RobotViewer

    view = RobotViewer(f"{prefix}_viewer", robot.model, robot.visual_model, robot.collision_model)
    q = robot.device.state.value
    with view.lock:
        view.viz.display(q)
    view.frameRobot(q)
    emit(
        f"viewer: open {view.url()} in a browser; the motion is replayed there at real "
        "time once it is computed"
    )
    return view


def replay(
    view: Any,
    configurations: Any,
    dt: float,
    hold: float | None,
    emit: Callable[[str], None],
) -> None:
    """Send the run (``configurations``: one row per tick of ``dt`` s, the start
    first) to ``view``, to be played in the page at real time and repeated, then keep
    the viewer up: until the page is closed (after it was opened) or Ctrl-C when
    ``hold`` is None, at most ``hold`` seconds otherwise (0: not at all)."""
    import numpy as np

    qs = np.asarray(configurations)
    # about VIEWER_FRAME s apart, evenly spaced from the first row to the last
    count = max(2, round((len(qs) - 1) * dt / VIEWER_FRAME) + 1) if len(qs) > 1 else 1
    rows = np.round(np.linspace(0, len(qs) - 1, count)).astype(int)
    frame = (len(qs) - 1) * dt / (count - 1) if count > 1 else dt
    duration = view.animate(qs[rows], frame)
    motion = f"the page replays the {duration:.2f} s motion at real time, again and again"
    if hold is not None and hold <= 0:
        emit(f"viewer: {motion}; closing now (--hold 0)")
        return
    menu = "(its Controls > Animations menu pauses, slows and scrubs it)"
    if hold is None:
        emit(f"viewer: {motion} {menu}; close the page or press Ctrl-C to quit")
    else:
        emit(f"viewer: {motion} {menu}; closing in {hold:g} s (Ctrl-C: now)")
    try:
        view.waitPages(timeout=hold)
    except KeyboardInterrupt:
        emit("")  # after the ^C the terminal shows
    emit("viewer: closed")


def viewer_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--viewer`` and ``--hold S``."""
    parser.add_argument(
        "--viewer",
        action="store_true",
        help="show the robot in a meshcat viewer (prints its address): the motion is "
        "replayed there at real time, again and again, until you close the page or "
        "press Ctrl-C",
    )
    parser.add_argument(
        "--hold",
        type=non_negative_float,
        metavar="S",
        help="with --viewer: keep the viewer up at most S seconds after the run (0: close "
        "it at once; default: until the page is closed or Ctrl-C)",
    )


def ui_options(parser: argparse.ArgumentParser, demo: bool = False) -> None:
    """Add ``--ui`` (the live dashboard, :class:`sotpy.dashboard.Dashboard`),
    ``--ui-port P``, ``--ui-host H`` and ``--ui-allow-remote`` (required with a host that is
    not loopback)."""
    g = parser.add_argument_group("dashboard (docs/dashboard.md)")
    what = (
        "build the demo's graph and serve it on a live web page, the loop paused at tick 1: "
        "start it, plot and edit from the page; Ctrl-C (or --hold S) ends"
        if demo
        else "serve a live web page over the graph and the loop (prints its address, with "
        "the token)"
    )
    g.add_argument("--ui", action="store_true", help=what)
    g.add_argument("--ui-port", type=int, default=0, metavar="P", help="its port (0: a free one)")
    g.add_argument(
        "--ui-host", default="127.0.0.1", metavar="H", help="its address (default 127.0.0.1)"
    )
    g.add_argument(
        "--ui-allow-remote",
        action="store_true",
        help="allow --ui-host to be an address other than loopback (the page is then "
        "reachable from the network, over plain HTTP: a warning says so)",
    )
    g.add_argument(
        "--loop-cpu",
        type=int,
        action="append",
        metavar="N",
        help="run the control loop's thread on CPU N (repeat for several) and the "
        "dashboard's threads on the others, so that they do not slow its ticks",
    )
    g.add_argument(
        "--loop-never-idle",
        action="store_true",
        help="the loop yields for the whole period instead of sleeping (spin = dt): its "
        "CPU never idles and its ticks run with warm caches, for a whole CPU's worth of "
        "power; use it with --loop-cpu",
    )


def loop_settings(args: argparse.Namespace) -> dict[str, Any]:
    """The :class:`~sotpy.loop.ControlLoop` keywords that ``--loop-cpu`` (``cpus``) and
    ``--loop-never-idle`` (``spin = dt``) ask for."""
    out: dict[str, Any] = {}
    cpus = getattr(args, "loop_cpu", None)
    if cpus:
        out["cpus"] = set(cpus)
    if getattr(args, "loop_never_idle", False):
        out["spin"] = args.dt
    return out


def open_dashboard(
    loop: Any, robot: Any, args: argparse.Namespace, token: str | None = None
) -> Any:
    """The :class:`~sotpy.dashboard.Dashboard` of ``loop`` that the ``--ui`` options of
    ``args`` ask for (``robot``: its ``model`` and ``visual_model``, for the 3-D view)."""
    from ..dashboard import Dashboard

    return Dashboard(
        loop,
        robot=robot,
        host=args.ui_host,
        port=args.ui_port,
        allowRemote=args.ui_allow_remote,
        token=token,
    )


def _demo_ui(args: argparse.Namespace, name: str, build: Callable[[], dict[str, Any]]) -> int:
    """``sotpy demo NAME --ui``: ``build()`` makes the demo's graph (its story run for one
    tick), then a :class:`~sotpy.loop.ControlLoop` (paused) and a dashboard serve it until
    Ctrl-C, or ``--hold S`` seconds."""
    import time
    import types

    from ..dynamics.robot import load_model
    from ..errors import SotpyError
    from ..graph import pool
    from ..loop import ControlLoop

    try:
        result = build()
        device = pool.getEntity(f"{result['prefix']}_device")
        model, visual, _ = load_model(args.robot)
        robot = types.SimpleNamespace(model=model, visual_model=visual)
        loop = ControlLoop(f"{result['prefix']}_loop", device, args.dt, **loop_settings(args))
        ui = open_dashboard(loop, robot, args)
    except SotpyError as exc:
        print(f"sotpy demo {name}: {exc}", file=sys.stderr)
        return 1
    if loop.cpus is not None:
        rest = loop.otherCpus()
        print(
            f"sotpy demo {name}: the loop's thread runs on CPU {sorted(loop.cpus)}, the "
            f"dashboard's on {'any' if rest is None else sorted(rest)}",
            flush=True,
        )
    if loop.spin >= loop.dt:
        print(
            f"sotpy demo {name}: the loop yields for the whole period (its CPU never idles)",
            flush=True,
        )
    print(
        f"sotpy demo {name}: the graph is built and the loop {loop.name} paused at tick "
        f"{device.state.time}; open the dashboard:\n  {ui.url()}\nStart the loop there (or "
        "Step), click a signal's 'plot', edit a gain. Ctrl-C ends.",
        flush=True,
    )
    try:
        if args.hold is None:
            while True:
                time.sleep(3600)
        else:
            time.sleep(args.hold)
    except KeyboardInterrupt:
        print("", flush=True)
    finally:
        loop.stop()
        ui.close()
        print(f"sotpy demo {name}: stopped; loop statistics:\n{loop.stats()}", flush=True)
    return 0


#: Defaults of ``sotpy demo robot``: robot name, simulated time (s), time step (s).
ROBOT_DEMO_DEFAULTS: dict[str, Any] = {"robot": "talos", "duration": 3.0, "dt": 1e-3}

#: The robots of the reaching demo: ``sotpy demo <robot>``.
REACH_ROBOTS: tuple[str, ...] = ("talos", "romeo", "nao")

#: Defaults of ``sotpy demo talos|romeo|nao``: simulated time (s), time step (s), the
#: margin of the CoM inside the support polygon (m).
REACH_DEMO_DEFAULTS: dict[str, Any] = {"duration": 2.0, "dt": 1e-3, "margin": 0.01}


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    v = _number(text)
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return v


def finite_float(text: str) -> float:
    """argparse type: a finite number."""
    v = _number(text)
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def robot_options(parser: argparse.ArgumentParser) -> None:
    """Add ``sotpy demo robot``'s options: ``--robot NAME``, ``--viewer``, ``--hold S``,
    ``--duration S``, ``--dt S`` and ``--plot PATH``."""
    d = ROBOT_DEMO_DEFAULTS
    parser.add_argument(
        "--robot",
        default=d["robot"],
        metavar="NAME",
        help=f"robot: a name listed by 'sotpy robots' or a .toml description "
        f"(default {d['robot']})",
    )
    viewer_options(parser)
    ui_options(parser, demo=True)
    parser.add_argument(
        "--duration",
        type=positive_float,
        default=d["duration"],
        metavar="S",
        help=f"simulated time, s (default {d['duration']:g})",
    )
    parser.add_argument(
        "--dt",
        type=positive_float,
        default=d["dt"],
        metavar="S",
        help=f"time step, s (default {d['dt']:g})",
    )
    parser.add_argument(
        "--plot", metavar="PATH", help="save the wrist, the CoM and the joints' travel (PNG)"
    )


def robot_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo robot`` with the parsed options: 0 when the feet did not move and
    no joint left its limits, 1 otherwise or on an error, 130 on Ctrl-C."""
    from ..errors import SotpyError
    from .robot_tour import run_robot_tour

    if args.ui:
        return _demo_ui(
            args,
            "robot",
            lambda: run_robot_tour(robot=args.robot, duration=args.dt, dt=args.dt, quiet=True),
        )
    try:
        result = run_robot_tour(
            robot=args.robot,
            duration=args.duration,
            dt=args.dt,
            viewer=args.viewer,
            hold=args.hold,
            plot=args.plot,
        )
    except SotpyError as exc:
        print(f"sotpy demo robot: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("sotpy demo robot: interrupted (the viewer, if any, is closed)", file=sys.stderr)
        return 130
    verdict = "OK" if result["ok"] else "FAILED"
    print(
        f"robot tour {verdict}: {result['robot']}, {result['ticks']} ticks in "
        f"{result['wall_time']:.2f} s ({_pace(result)})"
    )
    return 0 if result["ok"] else 1


def _pace(result: dict[str, Any]) -> str:
    """How the computation compares with real time, in words."""
    simulated, wall = result["duration"], result["wall_time"]
    if wall <= 0:
        return f"{simulated:g} s simulated"
    ratio = simulated / wall
    if ratio >= 1:
        return f"{simulated:g} s simulated, {ratio:.1f}x faster than real time"
    return f"{simulated:g} s simulated, {1 / ratio:.1f}x slower than real time"


def non_negative_float(text: str) -> float:
    """argparse type: a finite number >= 0."""
    v = _number(text)
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return v


def reach_options(parser: argparse.ArgumentParser, robot: str) -> None:
    """Add the options of ``sotpy demo <robot>`` (the reaching demo): ``--duration S``,
    ``--dt S``, ``--plot PATH``, ``--viewer``, ``--hold S``, ``--target-offset X Y Z``,
    ``--margin M``, ``--damping L``;
    ``robot`` is stored as the parsed ``robot``."""
    d = REACH_DEMO_DEFAULTS
    parser.set_defaults(robot=robot)
    parser.add_argument(
        "--duration",
        type=positive_float,
        default=d["duration"],
        metavar="S",
        help=f"simulated time, s (default {d['duration']:g})",
    )
    parser.add_argument(
        "--dt",
        type=positive_float,
        default=d["dt"],
        metavar="S",
        help=f"control period and time step, s (default {d['dt']:g})",
    )
    parser.add_argument(
        "--plot", metavar="PATH", help="save the task errors and the CoM path (PNG)"
    )
    viewer_options(parser)
    ui_options(parser, demo=True)
    parser.add_argument(
        "--target-offset",
        type=finite_float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        help="target minus the wrist's start, world axes, m (default: a reachable point "
        "0.2-0.25 m forward and up)",
    )
    parser.add_argument(
        "--margin",
        type=non_negative_float,
        default=d["margin"],
        metavar="M",
        help=f"the CoM stays this far inside the support polygon, m (default {d['margin']:g})",
    )
    parser.add_argument(
        "--damping",
        type=non_negative_float,
        default=0.0,
        metavar="L",
        help="damping of the wrist and posture levels, for targets out of reach "
        "(default 0: exact; the feet, CoM and joint limits stay exact)",
    )


def reach_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo <robot>`` with the parsed options: 0 when every check of the
    demo holds (wrist at the target, or stopped at the best reachable point; feet
    fixed; CoM inside; joints within their limits), 1 otherwise or on an error, 130 on
    Ctrl-C."""
    from ..errors import SotpyError
    from .reach import run_reach

    name = f"sotpy demo {args.robot}"
    if args.ui:
        return _demo_ui(
            args,
            args.robot,
            lambda: run_reach(
                robot=args.robot,
                duration=args.dt,
                dt=args.dt,
                target_offset=args.target_offset,
                quiet=True,
                margin=args.margin,
                damping=args.damping,
            ),
        )
    try:
        result = run_reach(
            robot=args.robot,
            duration=args.duration,
            dt=args.dt,
            target_offset=args.target_offset,
            plot=args.plot,
            viewer=args.viewer,
            hold=args.hold,
            margin=args.margin,
            damping=args.damping,
        )
    except SotpyError as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{name}: interrupted (the viewer, if any, is closed)", file=sys.stderr)
        return 130
    failed = [k for k, v in result["checks"].items() if not v]
    verdict = "OK" if result["ok"] else f"FAILED ({', '.join(failed)})"
    print(
        f"reach {verdict}: {result['robot']}, {result['ticks']} ticks in "
        f"{result['wall_time']:.2f} s ({_pace(result)})"
    )
    return 0 if result["ok"] else 1


# -- sotpy demo panda-torque --------------------------------------------------------
#: strategies of the torque-level controller (``sotpy.solvers.wbc.STRATEGIES``, not
#: imported here so that building the parser does not import Pinocchio)
TORQUE_STRATEGIES = ("OneLevelWeighted", "MultiLevelWeighted")


def torque_options(parser: argparse.ArgumentParser) -> None:
    """Options of ``sotpy demo panda-torque``: ``--duration S``, ``--strategy``,
    ``--plot PATH``."""
    parser.add_argument(
        "--duration",
        type=positive_float,
        default=2.0,
        metavar="S",
        help="duration of the minimum-jerk trajectory, s (then 0.5 s at the goal)",
    )
    parser.add_argument(
        "--strategy",
        choices=TORQUE_STRATEGIES,
        default="OneLevelWeighted",
        help="resolution strategy of the controller",
    )
    parser.add_argument("--plot", metavar="PATH", help="save torques and tracking error (PNG)")


def torque_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo panda-torque``: 0 when the hand ends within 1 mm of the goal
    with a solution at every tick, 1 otherwise or on an error."""
    from ..errors import SotpyError
    from .torque import run_panda_torque

    try:
        out = run_panda_torque(duration=args.duration, strategy=args.strategy, plot=args.plot)
    except SotpyError as exc:
        print(f"sotpy demo panda-torque: {exc}", file=sys.stderr)
        return 1
    ok = out["final_error"] < 1e-3 and out["solution_found"]
    print(
        f"panda-torque {'OK' if ok else 'FAILED'}: final error {1e3 * out['final_error']:.3f} mm,"
        f" max tracking error {1e3 * out['max_tracking_error']:.3f} mm,"
        f" max |tau|/limit {out['max_torque_ratio']:.2f},"
        f" solution every tick: {out['solution_found']}"
    )
    if out["plot"]:
        print(f"plot: {out['plot']}")
    return 0 if ok else 1


# -- sotpy demo talos-torque, torque-callbacks ----------------------------------------
def torque_talos_options(parser: argparse.ArgumentParser) -> None:
    """Options of ``sotpy demo talos-torque``: ``--duration S``, ``--settle S``,
    ``--side left|right``, ``--contacts floor|welded``, ``--strategy``, ``--plot PATH``."""
    parser.add_argument(
        "--duration",
        type=positive_float,
        default=1.0,
        metavar="S",
        help="duration of each CoM shift and of the reach, s (default 1.0)",
    )
    parser.add_argument(
        "--settle",
        type=non_negative_float,
        default=0.5,
        metavar="S",
        help="time at the goals afterwards, s (default 0.5)",
    )
    parser.add_argument(
        "--side",
        choices=("left", "right"),
        default="left",
        help="the foot the CoM moves over (default left)",
    )
    parser.add_argument(
        "--contacts",
        choices=("floor", "welded"),
        default="floor",
        help="the simulated feet: on a floor (MuJoCo, default) or welded",
    )
    parser.add_argument(
        "--strategy",
        choices=TORQUE_STRATEGIES,
        default="OneLevelWeighted",
        help="resolution strategy of the controller",
    )
    parser.add_argument(
        "--plot", metavar="PATH", help="save the contact forces, CoPs, torques and CoM (PNG)"
    )


def torque_talos_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo talos-torque``: 0 when its checks pass (``run_talos_torque``'s
    ``ok``: a solution every tick, the feet still, the simulated wrenches inside the
    cones with the CoPs inside the soles, the torque steps of the ramp within their
    bound, the CoM and the hand within 1 mm), 1 otherwise or on an error."""
    from ..errors import SotpyError
    from .torque import run_talos_torque

    try:
        out = run_talos_torque(
            duration=args.duration,
            settle=args.settle,
            side=args.side,
            contacts=args.contacts,
            strategy=args.strategy,
            plot=args.plot,
        )
    except SotpyError as exc:
        print(f"sotpy demo talos-torque: {exc}", file=sys.stderr)
        return 1
    print(out["summary"])
    if out["plot"]:
        print(f"plot: {out['plot']}")
    return 0 if out["ok"] else 1


def torque_callbacks_options(parser: argparse.ArgumentParser) -> None:
    """Options of ``sotpy demo torque-callbacks``: ``--no-compute``."""
    parser.add_argument(
        "--no-compute",
        action="store_true",
        help="hide onComputeBegin / onComputeEnd (printed every tick otherwise)",
    )


def torque_callbacks_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo torque-callbacks`` (prints the sequence): 0, or 1 on an error."""
    from ..errors import SotpyError
    from .torque import run_callbacks

    shown = "" if args.no_compute else ", onComputeBegin / onComputeEnd at every tick"
    print(  # on stderr: stdout holds the callbacks' lines only
        "torque-callbacks: the Panda in torque mode with a hand task 'ee' (ramp 2 ms), a "
        "posture task 'posture' (ramp 3 ms) and a torque limit 'torque' (no ramp); "
        "activateTasksAndConstraints() at tick 0, deactivateTasksAndConstraints() once "
        "all are active. Each callback prints: tick, time, object, callback, ramp (0 to "
        f"1){shown}.",
        file=sys.stderr,
        flush=True,
    )
    try:
        run_callbacks(compute=not args.no_compute)
    except SotpyError as exc:
        print(f"sotpy demo torque-callbacks: {exc}", file=sys.stderr)
        return 1
    return 0


def collision_options(parser: argparse.ArgumentParser) -> None:
    """Options of ``sotpy demo talos-collision``: ``--scenario torso|obstacle``,
    ``--duration S``, ``--dt S``, ``--safety M``, ``--influence M``, ``--gain V``,
    ``--viewer``, ``--hold S``."""
    parser.add_argument(
        "--scenario",
        choices=("torso", "obstacle"),
        default="torso",
        help="torso: the right hand to the left of the chest, across the body (default); "
        "obstacle: forward, past a ball in the way",
    )
    parser.add_argument(
        "--duration", type=positive_float, default=3.0, metavar="S", help="simulated time, s"
    )
    parser.add_argument(
        "--dt", type=positive_float, default=1e-3, metavar="S", help="time step, s (1e-3)"
    )
    parser.add_argument(
        "--safety",
        type=non_negative_float,
        default=0.01,
        metavar="M",
        help="safety distance d_s, m (default 0.01)",
    )
    parser.add_argument(
        "--influence",
        type=positive_float,
        default=0.05,
        metavar="M",
        help="influence distance d_i > d_s, m (default 0.05)",
    )
    parser.add_argument(
        "--gain",
        type=positive_float,
        default=0.5,
        metavar="V",
        help="the damper's xi: the largest approach speed at d_i, m/s (default 0.5)",
    )
    viewer_options(parser)


def collision_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo talos-collision``: 0 when every check holds (distance >= d_s at
    every tick, no chatter, collision level met, feet fixed, limits kept), 1 otherwise
    or on an error, 130 on Ctrl-C."""
    from ..errors import SotpyError
    from .collision import run_talos_collision

    try:
        result = run_talos_collision(
            scenario=args.scenario,
            duration=args.duration,
            dt=args.dt,
            safety=args.safety,
            influence=args.influence,
            gain=args.gain,
            viewer=args.viewer,
            hold=args.hold,
        )
    except (SotpyError, ValueError) as exc:
        print(f"sotpy demo talos-collision: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("sotpy demo talos-collision: interrupted", file=sys.stderr)
        return 130
    verdict = "OK" if result["ok"] else "FAILED"
    failed = [k for k, v in result["checks"].items() if not v]
    print(
        f"talos-collision {verdict}{': ' + ', '.join(failed) if failed else ''} "
        f"({result['ticks']} ticks in {result['wall_time']:.2f} s)"
    )
    return 0 if result["ok"] else 1


#: The robots of ``sotpy demo <robot>-walk``.
WALK_ROBOTS = ("talos", "romeo", "nao")


def _steps(text: str) -> int:
    """argparse type of ``--steps``: an integer >= 2 (a step forward, one to close)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if n < 2:
        raise argparse.ArgumentTypeError(f"expected at least 2 steps, got {n}")
    return n


def walk_options(parser: argparse.ArgumentParser, robot: str) -> None:
    """Options of ``sotpy demo <robot>-walk``: ``--steps N``, ``--step-length M``,
    ``--single-support S``, ``--double-support S``, ``--dt S``, ``--plot PATH``,
    ``--save FILE.npz``, ``--viewer``, ``--hold S``."""
    from .walk import GAITS

    gait = GAITS[robot]
    parser.add_argument(
        "--steps", type=_steps, default=gait.steps, help=f"swings, at least 2 ({gait.steps})"
    )
    parser.add_argument(
        "--step-length",
        type=positive_float,
        default=gait.length,
        metavar="M",
        help=f"each foot lands this far ahead of the other, m ({gait.length})",
    )
    parser.add_argument(
        "--single-support",
        type=positive_float,
        default=gait.ss,
        metavar="S",
        help=f"single support, s ({gait.ss})",
    )
    parser.add_argument(
        "--double-support",
        type=positive_float,
        default=gait.ds,
        metavar="S",
        help=f"double support, s ({gait.ds})",
    )
    parser.add_argument(
        "--dt", type=positive_float, default=1e-3, metavar="S", help="control period, s (1e-3)"
    )
    parser.add_argument(
        "--online",
        action="store_true",
        help="walk from velocitydes (the walking MPC): 0.1, 0.2, 0.3 m/s, a turn, a stop",
    )
    parser.add_argument(
        "--dynamic-filter",
        action="store_true",
        help="Kajita's second stage: the CoM corrected for the whole body's ZMP (a few s "
        "of planning)",
    )
    parser.add_argument(
        "--plot", metavar="PATH", help="save the top view and the ZMP's margin (PNG)"
    )
    parser.add_argument(
        "--save", metavar="FILE.npz", help="save t, q, v, the contact phase, the footprints"
    )
    viewer_options(parser)
    parser.set_defaults(walk_robot=robot)


def walk_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo <robot>-walk``: 0 when every check of the motion holds, 1
    otherwise or on an error, 130 on Ctrl-C."""
    from dataclasses import replace

    from ..errors import SotpyError
    from .walk import GAITS, ONLINE_GAITS, run_walk

    name = f"{args.walk_robot}-walk"
    table = ONLINE_GAITS if args.online else GAITS
    if args.online:  # the online gait's timing unless the options changed it
        defaults = GAITS[args.walk_robot]
        base = ONLINE_GAITS[args.walk_robot]
        if args.single_support == defaults.ss:
            args.single_support = base.ss
        if args.double_support == defaults.ds:
            args.double_support = base.ds
    gait = replace(
        table[args.walk_robot],
        steps=args.steps,
        length=args.step_length,
        ss=args.single_support,
        ds=args.double_support,
    )
    try:
        result = run_walk(
            args.walk_robot,
            gait=gait,
            dt=args.dt,
            online=args.online,
            dynamicFilter=args.dynamic_filter,
            plot=args.plot,
            save=args.save,
            viewer=args.viewer,
            hold=args.hold,
        )
    except (SotpyError, ValueError) as exc:
        print(f"sotpy demo {name}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"sotpy demo {name}: interrupted", file=sys.stderr)
        return 130
    failed = [k for k, v in result["checks"].items() if not v]
    print(f"{name} {'OK' if result['ok'] else 'FAILED: ' + ', '.join(failed)}")
    return 0 if result["ok"] else 1
