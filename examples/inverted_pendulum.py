"""SoT's inverted-pendulum tutorial: balance a cart-pole with LQR state feedback.

The graph, as in the SoT slides::

    a = InvertedPendulum("IP")          # cart-pole: input force, output state
    b = FeedbackController("K")         # input state, output force = -K . state
    plug(a.state, b.state)
    plug(b.force, a.force)
    a.state.value = (0.0, 0.1, 0.0, 0.0)
    a.incr(dt)                          # repeatedly, traced by a Tracer

Run it with ``python examples/inverted_pendulum.py [--plot pendulum.png]``; the same
story is ``sotpy demo pendulum``. The logic is :func:`sotpy.tutorial.run_pendulum`.
"""

import argparse

from sotpy.tutorial import run_pendulum


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--plot", metavar="PATH", help="save a plot of x, theta, force")
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time, s")
    parser.add_argument("--theta0", type=float, default=0.1, help="initial angle, rad")
    parser.add_argument("--dt", type=float, default=1e-3, help="time step, s")
    args = parser.parse_args()
    result = run_pendulum(duration=args.duration, dt=args.dt, theta0=args.theta0, plot=args.plot)
    print(f"{round(args.duration / args.dt)} ticks in {result['wall_time']:.2f} s")
    return 0 if result["converged"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
