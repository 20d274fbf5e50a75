"""Locomotion: the numerical core (preview control, the step plan and its swing
trajectories, the walking MPC, the dynamic filter: plain functions and classes over
arrays) and the entity over it (:class:`PatternGenerator`).

- :mod:`sotpy.walking.preview`: Kajita's preview control of the cart-table model;
- :mod:`sotpy.walking.plan`: footprints, timing, C2 swing trajectories, the ZMP reference;
- :mod:`sotpy.walking.mpc`: the velocity-referenced walking MPC (after Herdt et al. 2010);
- :mod:`sotpy.walking.walks`: the footstep walk and the velocity walk as functions of time;
- :mod:`sotpy.walking.dynamic_filter`: Kajita's second stage over the whole body;
- :mod:`sotpy.walking.pattern_generator`: the SoT's ``PatternGenerator`` entity.

docs/walking.md is the user's page.
"""

from .mpc import MPCParameters, MPCResult, VelocityMPC
from .pattern_generator import PatternGenerator, RobotGeometry, robotGeometry
from .plan import Footprint, Sole, StepPlan
from .preview import PreviewController, PreviewGains, previewGains
from .walks import FootstepWalk, VelocityWalk

__all__ = [
    "Footprint",
    "FootstepWalk",
    "MPCParameters",
    "MPCResult",
    "PatternGenerator",
    "PreviewController",
    "PreviewGains",
    "RobotGeometry",
    "Sole",
    "StepPlan",
    "VelocityMPC",
    "VelocityWalk",
    "previewGains",
    "robotGeometry",
]
