"""sot-core's ``meta_task_6d``: ``MetaTask6d`` (SoT's kinematic 6-D meta-task) and
``toFlags`` (a flag string, booleans, or row indices), served by sotpy."""

from ...._meta import MetaTask6d, toFlags

__all__ = ["MetaTask6d", "toFlags"]
