"""Locomotion: the numerical core (preview control, the step plan and its swing
trajectories: plain functions over arrays) and the entities over it
(:class:`PatternGenerator`).

- :mod:`sotpy.walking.preview`: Kajita's preview control of the cart-table model;
- :mod:`sotpy.walking.plan`: footprints, timing, C2 swing trajectories, the ZMP reference;
- :mod:`sotpy.walking.pattern_generator`: the SoT's ``PatternGenerator`` entity.

docs/walking.md is the user's page.
"""

from .pattern_generator import PatternGenerator, RobotGeometry, robotGeometry
from .plan import Footprint, Sole, StepPlan
from .preview import PreviewController, PreviewGains, previewGains

__all__ = [
    "Footprint",
    "PatternGenerator",
    "PreviewController",
    "PreviewGains",
    "RobotGeometry",
    "Sole",
    "StepPlan",
    "previewGains",
    "robotGeometry",
]
