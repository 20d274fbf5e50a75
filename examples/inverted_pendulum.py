"""SoT's inverted-pendulum tutorial: a cart-pole balanced by state feedback.

Two entities in a closed loop, as in the SoT slides: the pendulum's state feeds the
controller, whose force drives the cart. The loop is run for ``--duration`` seconds, a
tracer records the state and the force at every tick, and the run is printed (and
plotted with ``--plot pendulum.png``).

    python examples/inverted_pendulum.py                 # the default LQR gain
    python examples/inverted_pendulum.py --sot-gain      # the SoT tutorial's gain

The same story, with more checks, is ``sotpy demo pendulum``. Exit code 0 when the
pendulum ends upright and still.
"""

import argparse

from sotpy.graph import Tracer, plug
from sotpy.tutorial import (
    SOT_TUTORIAL_GAIN,
    FeedbackController,
    InvertedPendulum,
    hasFallen,
    isConverged,
    pendulumTable,
    plotPendulum,
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--plot", metavar="PATH", help="save a plot of x, theta, force")
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time, s")
    parser.add_argument("--theta0", type=float, default=0.1, help="initial angle, rad")
    parser.add_argument("--dt", type=float, default=1e-3, help="time step, s")
    parser.add_argument(
        "--sot-gain", action="store_true", help="use the SoT tutorial's gain (0, 27, 0.001, 0.001)"
    )
    args = parser.parse_args()

    # -- the graph ---------------------------------------------------------------------
    pendulum = InvertedPendulum("IP")  # M = m = 1 kg, l = 1 m, viscosity 0.1
    controller = FeedbackController("K")  # force = -K . state
    if args.sot_gain:
        controller.setGain(SOT_TUTORIAL_GAIN)
    plug(pendulum.state, controller.state)
    plug(controller.force, pendulum.force)
    pendulum.state.value = (0.0, args.theta0, 0.0, 0.0)  # (x, theta, x_dot, theta_dot)

    tracer = Tracer("tracer")
    tracer.add(pendulum.state, "state")
    tracer.add(controller.force, "force")
    tracer.setTimeStep(args.dt)
    tracer.setBufferSize(round(args.duration / args.dt) + 1)
    tracer.start()

    # -- the run -----------------------------------------------------------------------
    tracer.trigger.recompute(pendulum.state.time)  # the initial row
    for _ in range(round(args.duration / args.dt)):
        pendulum.incr(args.dt)  # reads force at the state's tick, writes the next state
        tracer.trigger.recompute(pendulum.state.time)
        if hasFallen(pendulum.state.value):
            print("the pendulum fell (|theta| > pi/2)")
            break

    # -- what happened -----------------------------------------------------------------
    data = tracer.data()
    print(pendulumTable(data))
    if args.plot:
        print(f"plot saved to {plotPendulum(data, args.plot)}")
    return 0 if isConverged(pendulum.state.value) else 1


if __name__ == "__main__":
    raise SystemExit(main())
