"""sot-talos' ``Talos`` robot class over sotpy's Talos (``load_robot("talos")``:
example-robot-data's reduced model, its op points and half-sitting)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...._errors import unsupported
from ..dynamic_pinocchio.humanoid_robot import AbstractHumanoidRobot, fromDescription

__all__ = ["Talos"]


class Talos(AbstractHumanoidRobot):
    """SoT's ``Talos(name, device=None, tracer=None, fromRosParam=False)``: sotpy's
    Talos with the entities ``name_dynamic`` and ``name_device``, and the op points
    left-/right-wrist, left-/right-ankle, gaze, waist and chest (``OperationalPointsMap``
    gives their Pinocchio frames). ``fromRosParam`` (the URDF of ROS's
    ``/robot_description``) and a real robot's ``device`` are not supported."""

    forceSensorInLeftAnkle = (
        (1.0, 0.0, 0.0, 0.0),
        (0.0, 1.0, 0.0, 0.0),
        (0.0, 0.0, 1.0, -0.107),
        (0.0, 0.0, 0.0, 1.0),
    )
    forceSensorInRightAnkle = forceSensorInLeftAnkle

    def __init__(
        self, name: str, device: Any = None, tracer: Any = None, fromRosParam: Any = False
    ) -> None:
        if fromRosParam:
            raise unsupported(
                "Talos(fromRosParam=True): the URDF of ROS's /robot_description parameter",
                "Talos(name) or load_robot('talos'): example-robot-data's Talos",
            )
        AbstractHumanoidRobot.__init__(self, name, tracer)
        fromDescription(self, "talos", name, device)

    def defineHalfSitting(self, q: np.ndarray) -> None:
        """sotpy's half-sitting of Talos (its SRDF reference posture)."""
        q[:] = self.sotpyRobot.halfSitting
