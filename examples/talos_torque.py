"""Talos on a floor, in torque mode: it shifts its CoM over one foot, reaches with its
right hand and shifts back (ORCA-style whole-body controller: unilateral 6-D foot
contacts with friction pyramids, CoP margins and pose feedback, the contact wrench
distribution cost, CoM, hand and posture tasks with PID servos, torque and position
limits, smooth activation ramps bounded in torque rate). The Device simulates the floor
with MuJoCo (four corners per sole), or welds the feet (``--contacts welded``).

    python examples/talos_torque.py [--side left] [--contacts floor] [--plot talos.png]

The checks printed (feet, contact forces, CoPs, torque steps, tracking) are computed
from the simulation, not from the controller: see ``docs/torque-control.md``.
"""

from __future__ import annotations

import argparse

from sotpy.demos.torque import run_talos_torque


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=1.0, help="each shift and the reach (s)")
    ap.add_argument("--settle", type=float, default=0.5, help="time at rest at the end (s)")
    ap.add_argument("--side", choices=("left", "right"), default="left")
    ap.add_argument("--contacts", choices=("floor", "welded"), default="floor")
    ap.add_argument("--strategy", default="OneLevelWeighted")
    ap.add_argument("--plot", default=None, help="PNG: contact forces, CoPs, torques, CoM")
    args = ap.parse_args()
    out = run_talos_torque(
        duration=args.duration,
        settle=args.settle,
        side=args.side,
        contacts=args.contacts,
        strategy=args.strategy,
        plot=args.plot,
    )
    print(f"feet slide / tilt        {1e3 * out['feet_slide']:.3f} mm, {out['feet_tilt']:.2e} rad")
    print(
        f"min normal force         {out['min_fz']:.1f} N (a corner: {out['min_point_force']:.1f} N)"
    )
    print(f"max |f_t| / (mu f_z)     {out['friction_ratio']:.3f}")
    print(f"min CoP margin           {1e3 * out['cop_margin']:.2f} mm (inside the soles)")
    print(f"max torque step in ramp  {out['max_rate_ratio']:.2f} of its bound")
    print(
        f"CoM / hand tracking      {1e3 * out['com_tracking']:.3f} / "
        f"{1e3 * out['hand_tracking']:.3f} mm"
    )
    print(f"max |tau| / limit        {out['max_torque_ratio']:.3f}")
    print(out["summary"])
    if out["plot"]:
        print(f"plot: {out['plot']}")


if __name__ == "__main__":
    main()
