"""The ``sotpy`` command line.

::

    sotpy demo pendulum [--plot PATH] [--duration S] [--theta0 RAD] [--dt S]
    sotpy demo robot [--robot NAME] [--duration S] [--viewer] [--dt S]
    sotpy demo talos|romeo|nao [--duration S] [--dt S] [--plot PATH] [--viewer]
                               [--target-offset X Y Z] [--margin M] [--damping L]
    sotpy robots

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
    finite_float,
    positive_float,
    reach_options,
    reach_run,
    robot_options,
    robot_run,
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


def _pendulum_run(args: argparse.Namespace) -> int:
    from .errors import SotpyError
    from .tutorial import run_pendulum

    try:
        result = run_pendulum(
            duration=args.duration, dt=args.dt, theta0=args.theta0, plot=args.plot
        )
    except SotpyError as exc:
        print(f"sotpy demo pendulum: {exc}", file=sys.stderr)
        return 1
    verdict = "converged" if result["converged"] else "did NOT converge"
    print(
        f"pendulum {verdict} (|theta| < 1e-3 rad and |theta_dot| < 1e-2 rad/s); "
        f"{len(result['time']) - 1} ticks in {result['wall_time']:.2f} s"
    )
    return 0 if result["converged"] else 1


DEMOS: dict[
    str,
    tuple[str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]],
] = {
    "pendulum": (
        "SoT's tutorial: an inverted pendulum balanced by LQR state feedback",
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
    for name in list_robots():
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


SUBCOMMANDS: list[Callable[[Any], None]] = [add_demo, add_robots]


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
