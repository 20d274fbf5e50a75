"""The ``sotpy`` command line.

::

    sotpy demo pendulum [--plot PATH] [--duration S] [--theta0 RAD] [--dt S] [--gain K K K K]
    sotpy demo robot [--robot NAME] [--duration S] [--viewer [--hold S]] [--dt S]
                     [--plot PATH]
    sotpy demo talos|romeo|nao [--duration S] [--dt S] [--plot PATH] [--viewer [--hold S]]
                               [--target-offset X Y Z] [--margin M] [--damping L]
    sotpy demo panda-torque [--duration S] [--strategy NAME] [--plot PATH]
    sotpy demo talos-torque [--duration S] [--settle S] [--side left|right]
                            [--contacts floor|welded] [--strategy NAME] [--plot PATH]
    sotpy demo talos-collision [--scenario torso|obstacle] [--duration S] [--dt S]
                               [--safety M] [--influence M] [--gain V] [--viewer [--hold S]]
    sotpy demo torque-callbacks [--no-compute]
    sotpy robots
    sotpy compile
    sotpy shell [ROBOT] [--dt S] [--no-ipython]
    sotpy serve [ROBOT] [--dt S] [--host H] [--port P] [--connection-file PATH] [--paused]
                [--zenoh PATH]
    sotpy connect [--connection-file PATH]
    sotpy run SCRIPT.py [ARG ...]

Each sub-command is a function ``add_<name>(subparsers)`` that adds its parser and sets
``func`` (the function run with the parsed arguments, returning the exit code); add a
sub-command by writing one and listing it in :data:`SUBCOMMANDS`. Demos are listed in
:data:`DEMOS` (name -> (help, function adding the demo's options, function running it)).
"""

import argparse
import functools
import sys
from collections.abc import Callable, Sequence
from typing import Any

from .demos import (
    REACH_ROBOTS,
    WALK_ROBOTS,
    collision_options,
    collision_run,
    finite_float,
    loop_settings,
    positive_float,
    reach_options,
    reach_run,
    robot_options,
    robot_run,
    torque_callbacks_options,
    torque_callbacks_run,
    torque_options,
    torque_run,
    torque_talos_options,
    torque_talos_run,
    ui_options,
    walk_options,
    walk_run,
)

__all__ = ["DEMOS", "SUBCOMMANDS", "build_parser", "main"]


# -- demos -----------------------------------------------------------------------------
def _pendulum_options(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("pendulum demo")
    g.add_argument("--plot", metavar="PATH", help="save a plot of x, theta and force (PNG)")
    g.add_argument(
        "--duration", type=positive_float, default=10.0, metavar="S", help="simulated time, s"
    )
    g.add_argument(
        "--theta0", type=finite_float, default=0.1, metavar="RAD", help="initial angle, rad"
    )
    g.add_argument("--dt", type=positive_float, default=1e-3, metavar="S", help="time step, s")
    g.add_argument(
        "--gain",
        type=finite_float,
        nargs=4,
        metavar="K",
        help="the controller's gain for (x, theta, x_dot, theta_dot), e.g. the SoT "
        "tutorial's 0 27 0.001 0.001 (default: the LQR gain)",
    )


def _pendulum_run(args: argparse.Namespace) -> int:
    from .errors import SotpyError
    from .tutorial import run_pendulum

    try:
        result = run_pendulum(
            duration=args.duration,
            dt=args.dt,
            theta0=args.theta0,
            plot=args.plot,
            gain=args.gain,
        )
    except SotpyError as exc:
        print(f"sotpy demo pendulum: {exc}", file=sys.stderr)
        return 1
    verdict = "converged" if result["converged"] else "did NOT converge"
    why = "; it fell" if result["fell"] else ""
    print(
        f"pendulum {verdict} (|theta| < 1e-3 rad and |theta_dot| < 1e-2 rad/s){why}; "
        f"{len(result['time']) - 1} ticks in {result['wall_time']:.2f} s"
    )
    return 0 if result["converged"] else 1


#: The demos of ``sotpy demo``: name -> (help, function adding the demo's options,
#: function running it and returning the exit status).
DEMOS: dict[
    str,
    tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]],
] = {
    "pendulum": (
        "SoT's tutorial: an inverted pendulum balanced by state feedback (LQR, or --gain)",
        _pendulum_options,
        _pendulum_run,
    ),
    "robot": (
        "a humanoid (default Talos) waves its arms and turns its head while standing; "
        "--viewer shows it",
        robot_options,
        robot_run,
    ),
}
DEMOS["panda-torque"] = (
    "torque control (ORCA-style): the Panda follows a minimum-jerk Cartesian trajectory "
    "with torque, position and velocity limits; --plot",
    torque_options,
    torque_run,
)
DEMOS["talos-torque"] = (
    "torque control (ORCA-style): Talos on a floor (friction cones, CoP in the soles) "
    "shifts its CoM over one foot, reaches with its right hand and shifts back; --plot",
    torque_talos_options,
    torque_talos_run,
)
DEMOS["talos-collision"] = (
    "self-collision and obstacle avoidance: Talos reaches across its body (or past a "
    "ball) with a collision level in its SOT; distances, chatter checked; --viewer",
    collision_options,
    collision_run,
)
DEMOS["torque-callbacks"] = (
    "torque control: the activation / deactivation callbacks of tasks and constraints, "
    "printed in the order they run",
    torque_callbacks_options,
    torque_callbacks_run,
)
for _robot in WALK_ROBOTS:
    DEMOS[f"{_robot}-walk"] = (
        f"the SoT's kinematic walk on {_robot.capitalize()}: PatternGenerator (preview "
        "control), feet, CoM, waist and posture over the SOT; the motion's multibody ZMP "
        "checked; --plot, --save, --viewer",
        functools.partial(walk_options, robot=_robot),
        walk_run,
    )
for _robot in REACH_ROBOTS:
    DEMOS[_robot] = (
        f"the SoT slides' reaching demo on {_robot.capitalize()}: feet fixed, CoM over the "
        "support polygon, right wrist to a target, half-sitting; --plot, --viewer",
        functools.partial(reach_options, robot=_robot),
        reach_run,
    )


def add_demo(subparsers: Any) -> None:
    """``sotpy demo NAME [options]``: one sub-parser per demo, with its own options."""
    p = subparsers.add_parser(
        "demo",
        help="run a demo",
        description="Run a demo. Exit code 0 when it succeeds. "
        "'sotpy demo NAME --help' lists a demo's options.",
    )
    names = p.add_subparsers(dest="name", metavar="NAME", required=True)
    for name, (helptext, options, run) in DEMOS.items():
        sp = names.add_parser(name, help=helptext, description=helptext)
        options(sp)
        sp.set_defaults(func=run)


# -- robots ----------------------------------------------------------------------------
def _robots_run(args: argparse.Namespace) -> int:
    from .dynamics.robot import RobotError, list_robots, robot_summary

    rows = [("robot", "nv", "actuated", "base", "source", "operational points")]
    failed = 0
    names = list_robots()
    print(  # on stderr, so that the table alone goes to stdout
        f"sotpy robots: loading the {len(names)} shipped models ({', '.join(names)}) to "
        "count their joints; a few seconds...",
        file=sys.stderr,
        flush=True,
    )
    for name in names:
        try:
            s = robot_summary(name)
        except RobotError as exc:
            print(f"sotpy robots: {exc}", file=sys.stderr)
            failed += 1
            continue
        rows.append(
            (
                s["name"],
                str(s["nv"]),
                str(s["actuated"]),
                "floating" if s["floating_base"] else "fixed",
                s["source"],
                ", ".join(f"{op}={frame}" for op, frame in s["opPoints"].items()),
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]) - 1)]
    for r in rows:
        print("  ".join(c.ljust(w) for c, w in zip(r[:-1], widths, strict=True)) + "  " + r[-1])
    print(
        "nv: velocity-space dimension (6 for a floating base + joints); actuated: joints "
        "minus couplings (e.g. Nao's HipYawPitch pair, mimic fingers)"
    )
    return 1 if failed else 0


def add_robots(subparsers: Any) -> None:
    """``sotpy robots``: the shipped robot descriptions."""
    p = subparsers.add_parser(
        "robots",
        help="list the robots sotpy ships",
        description="List the shipped robots: degrees of freedom, base, model source and "
        "operational points (SoT name=Pinocchio frame). Loads each model (a few seconds).",
    )
    p.set_defaults(func=_robots_run)


def _compile_run(args: argparse.Namespace) -> int:
    from . import _jit

    if not _jit.ENABLED:
        print("sotpy compile: nothing to compile (numba missing or SOTPY_JIT=0)")
        return 0
    done = _jit.compile_modules()
    names = list(_jit.EXPECTED_SECONDS)
    failed = [n for n in names if not _jit.ready(n)]
    for name in failed:
        print(f"sotpy compile: {name} could not be compiled", file=sys.stderr)
    if not failed:
        what = f"compiled {len(done)}, " if done else ""
        print(f"sotpy compile: every kernel module is ready ({what}{len(names)} in all)")
    return 1 if failed else 0


def add_compile(subparsers: Any) -> None:
    """``sotpy compile``: compile the per-tick kernels now rather than in a first run's
    background."""
    p = subparsers.add_parser(
        "compile",
        help="compile the per-tick kernels now (for a robot's install)",
        description="Compile every compiled per-tick kernel that is not in numba's cache "
        "yet, showing progress, and wait for any compile another sotpy run started. "
        "Without it a first run uses the NumPy kernels and compiles in the background "
        "(docs/solvers.md, 'First use on a machine'); run it once after installing on "
        "a robot, so that the first 1 kHz run is compiled. Exit code 1 if a module fails.",
    )
    p.set_defaults(func=_compile_run)


# -- shell, serve, connect -------------------------------------------------------------
def _robot_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "robot",
        nargs="?",
        default="talos",
        metavar="ROBOT",
        help="a robot listed by 'sotpy robots', or a .toml description (default talos)",
    )
    p.add_argument(
        "--dt",
        type=positive_float,
        default=1e-3,
        metavar="S",
        help="loop period and time step, s (default 0.001: 1 kHz)",
    )


def _shell_run(args: argparse.Namespace) -> int:
    from .errors import SotpyError
    from .shell import interact, makeNamespace

    try:
        ns = makeNamespace(args.robot, args.dt, **loop_settings(args))
        ui = _open_ui(args, ns) if args.ui else None
    except SotpyError as exc:
        print(f"sotpy shell: {exc}", file=sys.stderr)
        return 1
    try:
        interact(ns, ipython=False if args.no_ipython else None)
    finally:
        if ns.get("loop") is not None:
            ns["loop"].stop()
        if ui is not None:
            ui.close()
    return 0


def _open_ui(args: argparse.Namespace, ns: dict[str, Any], token: str | None = None) -> Any:
    """``--ui``: a dashboard over the namespace's loop, ``ui`` in the namespace."""
    from .demos import open_dashboard

    ui = open_dashboard(ns["loop"], ns.get("robot"), args, token=token)
    ns["ui"] = ui
    print(f"dashboard: {ui.url()}", flush=True)
    return ui


def add_shell(subparsers: Any) -> None:
    """``sotpy shell [ROBOT]``: an interactive console over the robot's graph."""
    p = subparsers.add_parser(
        "shell",
        help="interactive console with a robot's graph and its control loop (paused)",
        description="An interactive console (IPython if installed) with the robot loaded, "
        "a ControlLoop 'loop' started paused, the entities in the namespace and the "
        "helpers start(), stop(), step(n), stats(), writeGraph(path). See docs/shell.md.",
    )
    _robot_arg(p)
    p.add_argument(
        "--no-ipython",
        action="store_true",
        help="use Python's standard console (default: IPython when installed, "
        "pip install 'sotpy[shell]')",
    )
    ui_options(p)
    p.set_defaults(func=_shell_run)


def _serve_run(args: argparse.Namespace) -> int:
    import logging
    import signal
    import time

    from .errors import SotpyError
    from .remote import RemoteServer, _isLoopback, defaultConnectionFile
    from .shell import makeNamespace

    try:
        loopback = _isLoopback(args.host)
    except SotpyError as exc:
        print(f"sotpy serve: {exc}", file=sys.stderr)
        return 2
    if not loopback:
        if not args.allow_remote:
            print(
                f"sotpy serve: --host {args.host} is not a loopback address: the token and "
                "every line would travel unencrypted on the network. Add --allow-remote to "
                "do it anyway, or keep 127.0.0.1 and use an SSH tunnel (ssh -L).",
                file=sys.stderr,
            )
            return 2
        print(
            f"sotpy serve: WARNING: listening on {args.host}: the token and every line "
            "travel unencrypted; anyone on the network path can read them",
            file=sys.stderr,
            flush=True,
        )
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    try:
        ns = makeNamespace(args.robot, args.dt, **loop_settings(args))
    except SotpyError as exc:
        print(f"sotpy serve: {exc}", file=sys.stderr)
        return 1
    bridge = None
    if args.zenoh:  # publish and subscribe signals over Zenoh (sotpy.bridge.serve)
        from .bridge.serve import ServeBridge, loadServeConfig

        try:
            bridge = ServeBridge(loadServeConfig(args.zenoh), ns["robot"].device)
        except SotpyError as exc:
            print(f"sotpy serve: {exc}", file=sys.stderr)
            return 1
    path = args.connection_file or defaultConnectionFile()
    try:
        server = RemoteServer(
            ns, host=args.host, port=args.port, connectionFile=path, allow_remote=not loopback
        )
    except OSError as exc:
        print(f"sotpy serve: cannot listen on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 1
    loop = ns["loop"]
    try:  # the same token as the remote interpreter: one secret, in the connection file
        ui = _open_ui(args, ns, token=server.token) if args.ui else None
    except SotpyError as exc:
        server.stop()
        print(f"sotpy serve: {exc}", file=sys.stderr)
        return 1

    why = ["an error"]

    def _terminate(signum: int, frame: Any) -> None:
        why[0] = "SIGTERM"
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, _terminate)
    try:
        try:
            server.start()  # writes the connection file
        except SotpyError as exc:  # e.g. a connection file directory others may write
            print(f"sotpy serve: {exc}", file=sys.stderr)
            return 1
        if bridge is not None:
            bridge.ready(lambda text: print(text, flush=True))
        if not args.paused:
            loop.start()
        host, port = server.address
        print(
            f"sotpy serve: {args.robot} loop {'paused' if args.paused else 'running'} at "
            f"{1 / args.dt:g} Hz; remote interpreter on {host}:{port}; token in {path}; "
            "Ctrl-C or SIGTERM stops it",
            flush=True,
        )
        while True:
            time.sleep(3600)  # SIGINT/SIGTERM raise KeyboardInterrupt here
    except KeyboardInterrupt:
        why[0] = "Ctrl-C" if why[0] == "an error" else why[0]
    finally:
        server.stop()
        loop.stop()
        if ui is not None:
            ui.close()
        print(f"sotpy serve: stopped by {why[0]}; loop statistics:\n{loop.stats()}", flush=True)
    return 0


def add_serve(subparsers: Any) -> None:
    """``sotpy serve [ROBOT]``: the loop plus a remote interpreter."""
    p = subparsers.add_parser(
        "serve",
        help="run the control loop with a remote interpreter (sotpy connect)",
        description="Load the robot, run its ControlLoop in real time and serve a remote "
        "interpreter on HOST:PORT; clients must present the token written to the "
        "connection file (mode 0600). Ctrl-C or SIGTERM stops. See docs/shell.md.",
    )
    _robot_arg(p)
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (127.0.0.1)")
    p.add_argument(
        "--allow-remote",
        action="store_true",
        help="accept a --host that is not loopback (the channel is NOT encrypted)",
    )
    p.add_argument("--port", type=int, default=0, help="TCP port (0: a free one)")
    p.add_argument("--connection-file", metavar="PATH", help="where to write address+token")
    p.add_argument("--paused", action="store_true", help="do not start the loop")
    p.add_argument(
        "--zenoh", metavar="PATH", help="publish/subscribe signals over Zenoh (docs/zenoh.md)"
    )
    ui_options(p)
    p.set_defaults(func=_serve_run)


def _connect_run(args: argparse.Namespace) -> int:
    from .errors import SotpyError
    from .remote import RemoteClient

    try:
        client = RemoteClient.fromFile(args.connection_file)
    except SotpyError as exc:
        print(f"sotpy connect: {exc}", file=sys.stderr)
        return 1
    try:
        client.interact()
    except SotpyError as exc:
        print(f"sotpy connect: {exc}", file=sys.stderr)
        return 1
    finally:
        client.close()
    return 0


def add_connect(subparsers: Any) -> None:
    """``sotpy connect``: a console whose lines run in a ``sotpy serve`` process."""
    p = subparsers.add_parser(
        "connect",
        help="open a console on a running 'sotpy serve'",
        description="A console whose lines run in the 'sotpy serve' process (address and "
        "token from the connection file). Ctrl-D leaves; the server keeps running.",
    )
    p.add_argument("--connection-file", metavar="PATH", help="written by sotpy serve")
    p.set_defaults(func=_connect_run)


# -- run ---------------------------------------------------------------------------------
def _run_run(args: argparse.Namespace) -> int:
    import traceback

    from .compat import run

    try:
        return run(args.script, args.args)
    except FileNotFoundError as exc:
        print(exc, file=sys.stderr)
        return 2
    except Exception:
        traceback.print_exc()
        return 1


def add_run(subparsers: Any) -> None:
    """``sotpy run SCRIPT.py [ARG ...]``: a SoT Python script, unmodified."""
    p = subparsers.add_parser(
        "run",
        help="run a SoT Python script unmodified (its dynamic_graph imports served by sotpy)",
        description="Run a Stack of Tasks Python script as it is: its imports of "
        "dynamic_graph (dynamic-graph-python, sot-core, sot-dynamic-pinocchio, sot-talos, "
        "sot-tools, the tutorial) are served by sotpy for the run. What sotpy does not "
        "provide raises an error naming the SoT feature and sotpy's equivalent. Exit "
        "code: the script's (1 if it raised). See docs/porting.md.",
    )
    p.add_argument("script", metavar="SCRIPT.py", help="the SoT script")
    p.add_argument("args", nargs=argparse.REMAINDER, metavar="ARG", help="its arguments")
    p.set_defaults(func=_run_run)


#: The functions that each add one sub-command to the parser's sub-parsers.
SUBCOMMANDS: list[Callable[[Any], None]] = [add_demo, add_robots, add_compile]
SUBCOMMANDS += [add_shell, add_serve, add_connect]
SUBCOMMANDS += [add_run]


# -- entry point -----------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """The ``sotpy`` argument parser, with every sub-command of :data:`SUBCOMMANDS`."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="sotpy", description="The Stack of Tasks in Python: demos and tools."
    )
    parser.add_argument("--version", action="version", version=f"sotpy {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add in SUBCOMMANDS:
        add(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``sotpy`` command line with ``argv`` (default: ``sys.argv[1:]``).

    Returns the exit code (argparse's 2 for a usage error, 0 for ``--help``).
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, usage errors
        return exc.code if isinstance(exc.code, int) else 1
    return int(args.func(args))
