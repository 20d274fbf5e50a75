"""Talos stands on both feet, shifts its CoM over one foot and reaches with its right
hand, in torque mode (ORCA-style whole-body controller: unilateral 6-D foot contacts with
friction pyramids and CoP constraints, CoM, hand and posture tasks, torque and position
limits; the Device simulates the contacts).

    python examples/talos_torque.py [--side left] [--plot talos_torque.png]
"""

from __future__ import annotations

import argparse

from sotpy.demos.torque import run_talos_torque


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=1.5, help="motion duration (s)")
    ap.add_argument("--settle", type=float, default=0.5, help="time at the goals (s)")
    ap.add_argument("--side", choices=("left", "right"), default="left")
    ap.add_argument("--strategy", default="OneLevelWeighted")
    ap.add_argument("--plot", default=None, help="PNG path: contact forces, CoPs, CoM")
    args = ap.parse_args()
    out = run_talos_torque(
        duration=args.duration,
        settle=args.settle,
        side=args.side,
        strategy=args.strategy,
        plot=args.plot,
    )
    print(f"feet drift            {out['feet_drift']:.2e} m, {out['feet_rotation']:.2e} rad")
    print(f"min normal force      {out['min_fz']:.1f} N")
    print(f"max |f_t| / (mu f_z)  {out['friction_ratio']:.3f}")
    print(f"min CoP margin        {1e3 * out['cop_margin']:.2f} mm (inside the soles)")
    print(f"CoM to goal           {1e3 * out['com_error']:.3f} mm")
    print(f"hand to goal          {1e3 * out['hand_error']:.3f} mm")
    print(f"max |tau| / limit     {out['max_torque_ratio']:.3f}")
    print(f"solution every tick   {out['solution_found']}")
    if out["plot"]:
        print(f"plot: {out['plot']}")


if __name__ == "__main__":
    main()
