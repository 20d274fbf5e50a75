"""The import hook of ``sotpy run``: serves ``dynamic_graph`` and its submodules from
``sotpy.compat.dynamic_graph``.

``SoTFinder``, once in ``sys.meta_path`` (first), answers every import of
``dynamic_graph`` or ``dynamic_graph.<...>``:

- a module sotpy serves is imported as ``sotpy.compat.<name>`` and the same module
  object is registered under ``<name>`` too, so ``dynamic_graph.sot.core.sot.SOT`` is
  ``sotpy.solvers.SOT`` and each module exists once;
- a module of ``sotpy.compat._table.MODULES`` (one of the many sot-core modules
  that only hold entity classes) is built from that table: a module whose attributes
  are sotpy's classes;
- a SoT module sotpy knows it does not serve (``dynamic_graph.ros``, ...) raises
  :class:`~sotpy.compat.UnsupportedModule` (an ``ImportError``) naming it and sotpy's
  equivalent;
- any other ``dynamic_graph`` module raises the same error, listing the served ones.

The finder is installed only by :func:`sotpy.compat.install` (``sotpy run``,
``python -m sotpy.compat``); a plain ``import sotpy`` never installs it, so a real SoT
installed beside sotpy keeps its ``dynamic_graph``.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from types import ModuleType
from typing import Any

from ._errors import UnsupportedModule
from ._table import MODULES

__all__ = ["NOT_SERVED", "PREFIX", "ROOT", "SoTFinder"]

ROOT = "dynamic_graph"
PREFIX = "sotpy.compat."

#: SoT modules the layer knows and does not serve, with sotpy's equivalent.
NOT_SERVED: dict[str, str] = {
    "dynamic_graph.ros": "no ROS bridge: sotpy serve / sotpy connect (a remote "
    "interpreter) and Tracer files (docs/shell.md)",
    "dynamic_graph_bridge": "sotpy serve / sotpy connect (docs/shell.md)",
    "dynamic_graph.sot.core.parameter_server": "the robot descriptions of sotpy "
    "(sotpy/robots/*.toml, load_robot)",
    "dynamic_graph.sot.talos.sot_talos_device": "a simulated Device: the robot's "
    "robot.device (load_robot); sotpy does not drive a real robot",
    "dynamic_graph.sot.core.meta_tasks_kine_relative": "two MetaTaskKine6d, or a "
    "FeaturePose on an Inverse_of_matrixHomo * Multiply_of_matrixHomo placement",
    "dynamic_graph.sot.core.feature_point6d_relative": "a FeaturePose on a relative "
    "placement (Inverse_of_matrixHomo, Multiply_of_matrixHomo)",
    "dynamic_graph.sot.core.task_pd": "Task with setWithDerivative(True)",
    "dynamic_graph.sot.core.task_unilateral": "TaskInequality (bounds on the error, any "
    "priority level)",
    "dynamic_graph.sot.core.feature_pose": "sot-core's relative FeaturePose (oMja, oMjb, "
    "...) is not ported: FeaturePoint6d, or sotpy's FeaturePose on a placement composed "
    "with Inverse_of_matrixHomo and Multiply_of_matrixHomo",
    "dynamic_graph.sot.core.task_conti": "Task (sotpy inserts a task without smoothing)",
    "dynamic_graph.sot.core.feature_line_distance": "FeatureGeneric with your own "
    "error and Jacobian",
    "dynamic_graph.sot.core.feature_vector3": "FeaturePose with selec '000111'",
    "dynamic_graph.sot.core.robot_utils": "load_robot and the robot descriptions",
    "dynamic_graph.sot.torque_control": "sotpy's torque-level controller (docs/torque-control.md)",
    "dynamic_graph.sot.application.acceleration": "sotpy's torque-level controller "
    "(docs/torque-control.md)",
}


def _served(fullname: str) -> bool:
    """Whether ``sotpy.compat.<fullname>`` exists (without importing it)."""
    try:
        return importlib.util.find_spec(PREFIX + fullname) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


class _AliasLoader(importlib.abc.Loader):
    """Loads ``<name>`` as the module ``sotpy.compat.<name>`` (the same object)."""

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        return importlib.import_module(PREFIX + spec.name)

    def exec_module(self, module: ModuleType) -> None:
        """Nothing: ``create_module`` returned the executed module."""


class _TableLoader(importlib.abc.Loader):
    """Builds a module of :data:`MODULES`: its names taken from sotpy's modules."""

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return None  # a plain module

    def exec_module(self, module: ModuleType) -> None:
        source, names = MODULES[module.__name__]
        where = importlib.import_module(source)
        module.__doc__ = (
            f"SoT's {module.__name__}, served by sotpy: {', '.join(names)} from {source}."
        )
        for n in names:
            module.__dict__[n] = getattr(where, n)
        module.__all__ = list(names)


class _RefusingLoader(importlib.abc.Loader):
    """Raises :class:`UnsupportedModule` for a module the layer does not serve."""

    def __init__(self, equivalent: str) -> None:
        self.equivalent = equivalent

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        raise UnsupportedModule(spec.name, self.equivalent)

    def exec_module(self, module: ModuleType) -> None:  # pragma: no cover - never reached
        raise AssertionError("unreachable")


class SoTFinder(importlib.abc.MetaPathFinder):
    """Serves ``dynamic_graph...`` from ``sotpy.compat.dynamic_graph...`` (see the
    module doc)."""

    def find_spec(
        self, fullname: str, path: Any = None, target: Any = None
    ) -> importlib.machinery.ModuleSpec | None:
        top = fullname.partition(".")[0]
        if top not in (ROOT, "dynamic_graph_bridge"):
            return None
        for name, equivalent in NOT_SERVED.items():
            if fullname == name or fullname.startswith(name + "."):
                return importlib.machinery.ModuleSpec(fullname, _RefusingLoader(equivalent))
        if fullname in MODULES:
            return importlib.machinery.ModuleSpec(fullname, _TableLoader())
        if top == ROOT and _served(fullname):
            spec = importlib.machinery.ModuleSpec(fullname, _AliasLoader())
            return spec
        served = ", ".join(_servedModules())
        return importlib.machinery.ModuleSpec(
            fullname,
            _RefusingLoader(f"none known; the modules it serves: {served} (docs/porting.md)"),
        )


def _servedModules() -> list[str]:
    """The ``dynamic_graph`` modules the layer serves (from its package tree)."""
    import pkgutil

    from . import dynamic_graph

    names = [ROOT, *MODULES]
    for info in pkgutil.walk_packages(dynamic_graph.__path__, ROOT + "."):
        if not info.name.rsplit(".", 1)[-1].startswith("_"):
            names.append(info.name)
    return sorted(set(names))


def installed() -> bool:
    """Whether a ``SoTFinder`` is in ``sys.meta_path``."""
    return any(isinstance(f, SoTFinder) for f in sys.meta_path)
