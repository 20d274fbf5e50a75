# A SoT user's pendulum script, in the style of dynamic-graph-tutorial's simu.py: the
# tutorial's module names, signals fetched by name, numpy values, the tutorial's gain
# (0, 27, 0.001, 0.001) and a fixed-step loop of incr. It imports nothing from sotpy.
#
#     sotpy run simu.py [STEPS] [OUT.npz]
import sys

import dynamic_graph as dg
import dynamic_graph.tutorial as dgt
import numpy as np

DT = 0.001


def make_loop():
    pendulum = dgt.InvertedPendulum("IP")
    pendulum.setCartMass(1.0)
    pendulum.setPendulumMass(1.0)
    pendulum.setPendulumLength(1.0)
    controller = dgt.FeedbackController("K")

    state = pendulum.signal("state")
    force = pendulum.signal("force")
    dg.plug(state, controller.signal("state"))
    dg.plug(controller.signal("force"), force)

    state.value = np.array((0.0, 0.1, 0.0, 0.0))  # leaning by 0.1 rad
    controller.setGain(np.array((0.0, 27.0, 0.001, 0.001)))
    return pendulum, state, force


def simulate(steps):
    pendulum, state, force = make_loop()
    times, states, forces = [], [], []
    for k in range(steps):
        times.append(k * DT)
        states.append(state.value)
        forces.append(force.value)
        pendulum.incr(DT)
    return np.array(times), np.array(states), np.array(forces)


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    t, s, f = simulate(n)
    print("theta after %g s: %g rad" % (n * DT, s[-1][1]))
    if len(sys.argv) > 2:
        np.savez(sys.argv[2], time=t, state=s, force=f)
