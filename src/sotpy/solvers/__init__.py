"""Numerical core of the hierarchical task solvers (no graph).

``solve_hierarchy(levels, damping=0.0)`` returns the lexicographic optimum of a stack of
levels ``lower_k <= A_k x <= upper_k`` (equalities where ``lower == upper``), with the
minimum-norm solution among the optimal ones; :class:`HierarchySolver` is the persistent
version (buffers and the warm start kept between calls) that the SOT entity
keeps between ticks, and :class:`SOT` is that entity. See
:mod:`sotpy.solvers.hierarchy` and ``docs/solvers.md``.

The torque-level whole-body controller (ORCA-style) is :mod:`sotpy.solvers.wbc` (the
numerical core) and :class:`sotpy.solvers.controller.Controller` (the entity); see
``docs/torque-control.md``.
"""

from ..errors import SolverError
from .hierarchy import HierarchyResult, HierarchySolver, solve_hierarchy
from .sot import SOT

__all__ = ["SOT", "HierarchyResult", "HierarchySolver", "SolverError", "solve_hierarchy"]
