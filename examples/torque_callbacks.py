"""The activation and deactivation life cycle of the torque-level controller's tasks and
constraints: every callback (onActivation, onComputeBegin, onComputeEnd, onActivated,
onDeactivation, onDeactivated) prints a line, with the tick and the ramp.

    python examples/torque_callbacks.py [--no-compute]
"""

from __future__ import annotations

import argparse

from sotpy.demos.torque import run_callbacks


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--no-compute", action="store_true", help="hide onComputeBegin / onComputeEnd")
    args = ap.parse_args()
    run_callbacks(compute=not args.no_compute)


if __name__ == "__main__":
    main()
