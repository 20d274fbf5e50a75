"""Signal types of the robotics layers."""

from __future__ import annotations

import pinocchio as pin

from ..graph.types import object_type

__all__ = ["SE3"]

#: ``pinocchio.SE3`` placements; traced as the 16 entries of the homogeneous matrix
#: (row-major).
SE3 = object_type("SE3", pin.SE3, to_array=lambda M: M.homogeneous.ravel())
