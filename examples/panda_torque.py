"""The Panda follows a minimum-jerk Cartesian trajectory in torque mode (ORCA-style
whole-body controller with torque, position and velocity limits).

    python examples/panda_torque.py [--plot panda_torque.png]
"""

from __future__ import annotations

import argparse

from sotpy.demos.torque import run_panda_torque


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=2.0, help="trajectory duration (s)")
    ap.add_argument("--strategy", default="OneLevelWeighted")
    ap.add_argument("--plot", default=None, help="PNG path for torques and tracking error")
    args = ap.parse_args()
    out = run_panda_torque(duration=args.duration, strategy=args.strategy, plot=args.plot)
    print(f"final position error {1e3 * out['final_error']:.3f} mm")
    print(f"max tracking error   {1e3 * out['max_tracking_error']:.3f} mm")
    print(f"max |tau| / limit    {out['max_torque_ratio']:.3f}")
    print(f"solution every tick  {out['solution_found']}")
    if out["plot"]:
        print(f"plot: {out['plot']}")


if __name__ == "__main__":
    main()
