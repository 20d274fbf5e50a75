"""Demos: short stories that run a graph end to end, each a function the ``sotpy demo``
command line and a script of ``examples/`` call.

- :mod:`sotpy.demos.robot_tour`: a humanoid waves its arms and turns its head while
  standing, :func:`~sotpy.demos.robot_tour.run_robot_tour`; ``sotpy demo robot``
  (options :func:`robot_options`, runner :func:`robot_run`, registered in
  ``sotpy.cli.DEMOS``).

The pendulum tutorial (``sotpy demo pendulum``) lives in :mod:`sotpy.tutorial`.

This package only holds the command-line glue, so that building the ``sotpy`` parser
does not import Pinocchio; the demos are imported when they run (``from
sotpy.demos.robot_tour import run_robot_tour``).
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

__all__ = [
    "ROBOT_DEMO_DEFAULTS",
    "finite_float",
    "positive_float",
    "robot_options",
    "robot_run",
]

#: Defaults of ``sotpy demo robot``: robot name, simulated time (s), time step (s).
ROBOT_DEMO_DEFAULTS: dict[str, Any] = {"robot": "talos", "duration": 3.0, "dt": 1e-3}


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
    """Add ``sotpy demo robot``'s options: ``--robot NAME``, ``--viewer``,
    ``--duration S`` and ``--dt S``."""
    d = ROBOT_DEMO_DEFAULTS
    parser.add_argument(
        "--robot",
        default=d["robot"],
        metavar="NAME",
        help=f"robot: a name listed by 'sotpy robots' or a .toml description "
        f"(default {d['robot']})",
    )
    parser.add_argument(
        "--viewer",
        action="store_true",
        help="show the robot in a meshcat viewer (prints its address) and run at real time",
    )
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


def robot_run(args: argparse.Namespace) -> int:
    """Run ``sotpy demo robot`` with the parsed options: 0 when the feet did not move and
    no joint left its limits, 1 otherwise or on an error, 130 on Ctrl-C."""
    from ..errors import SotpyError
    from .robot_tour import run_robot_tour

    try:
        result = run_robot_tour(
            robot=args.robot, duration=args.duration, dt=args.dt, viewer=args.viewer
        )
    except SotpyError as exc:
        print(f"sotpy demo robot: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("sotpy demo robot: interrupted (the viewer is closed)", file=sys.stderr)
        return 130
    verdict = "OK" if result["ok"] else "FAILED"
    print(
        f"robot tour {verdict}: {result['robot']}, {result['ticks']} ticks in "
        f"{result['wall_time']:.2f} s"
    )
    return 0 if result["ok"] else 1
