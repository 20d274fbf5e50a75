"""Torque-level whole-body control in the style of ORCA: the numerical core (no graph).

The decision vector is ``chi = (a, tau, f)`` (:mod:`.model`), the equations of motion
``M a + b = S^T tau + J_c^T f`` a hard equality, tasks weighted least-squares rows
(:mod:`.tasks`), constraints ``lb <= C chi <= ub`` (:mod:`.constraints`; collision
avoidance: :mod:`.collision`), resolved by
one weighted QP or by strict levels (:mod:`.solver`); activation ramps and callbacks
(:mod:`.activation`); servos and the minimum-jerk profile (:mod:`.servos`). The graph
entities are in :mod:`sotpy.solvers.controller`. See ``docs/torque-control.md``.
"""

from .activation import CALLBACKS, RAMP_FLOOR, Activatable, ramp_weight
from .collision import CollisionConstraint
from .constraints import (
    Constraint,
    ContactConstraint,
    ContactState,
    JointAccelerationLimit,
    JointPositionLimit,
    JointTorqueLimit,
    JointVelocityLimit,
    dynamics_rows,
    friction_rows,
)
from .model import BilateralContactSpec, ContactSpec, Layout, RobotModel
from .servos import (
    check_gains,
    joint_pd,
    min_jerk,
    min_jerk_scalar,
    pid_step,
    pose_error,
    pose_pd,
    wrench_pi,
)
from .solver import STRATEGIES, Solution, WholeBodyController
from .tasks import (
    CartesianAccelerationTask,
    CoMAccelerationTask,
    ContactWrenchCost,
    JointAccelerationTask,
    RegularisationTask,
    Task,
    TorqueTask,
    WrenchTask,
)

__all__ = [
    "CALLBACKS",
    "RAMP_FLOOR",
    "STRATEGIES",
    "Activatable",
    "BilateralContactSpec",
    "CartesianAccelerationTask",
    "CoMAccelerationTask",
    "CollisionConstraint",
    "Constraint",
    "ContactConstraint",
    "ContactSpec",
    "ContactState",
    "ContactWrenchCost",
    "JointAccelerationLimit",
    "JointAccelerationTask",
    "JointPositionLimit",
    "JointTorqueLimit",
    "JointVelocityLimit",
    "Layout",
    "RegularisationTask",
    "RobotModel",
    "Solution",
    "Task",
    "TorqueTask",
    "WholeBodyController",
    "WrenchTask",
    "check_gains",
    "dynamics_rows",
    "friction_rows",
    "joint_pd",
    "min_jerk",
    "min_jerk_scalar",
    "pid_step",
    "pose_error",
    "pose_pd",
    "ramp_weight",
    "wrench_pi",
]
