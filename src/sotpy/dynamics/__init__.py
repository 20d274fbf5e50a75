"""Robots over Pinocchio: kinematics and dynamics as signals, simulated devices.

Conventions (written once, tested against finite differences):

- configurations ``q`` are Pinocchio configurations (free-flyer: position, then the
  quaternion ``(x, y, z, w)``), velocities ``v`` live in the tangent space (free-flyer:
  linear then angular velocity, expressed in the base frame);
- operational-point Jacobians are **LOCAL** (as in the SoT): the 6 x nv matrix ``J``
  such that the spatial velocity of the frame expressed in the frame itself is
  ``(v, w) = J v_q`` (linear first).

``Dynamic`` computes kinematics and dynamics signals, ``Device`` simulates a robot, and
``load_robot`` builds both for a robot shipped in ``sotpy/robots`` (``list_robots()``).
"""

from .device import Device, RobotSimu
from .dynamic import Dynamic
from .robot import Robot, list_robots, load_model, load_robot, robot_info
from .types import SE3

__all__ = [
    "SE3",
    "Device",
    "Dynamic",
    "Robot",
    "RobotSimu",
    "list_robots",
    "load_model",
    "load_robot",
    "robot_info",
]
