"""sot-core's ``meta_task_posture``: ``MetaTaskPosture`` and ``MetaTaskKinePosture``,
served by sotpy (see :mod:`sotpy.compat._meta`)."""

from ...._meta import MetaTaskKinePosture, MetaTaskPosture

__all__ = ["MetaTaskKinePosture", "MetaTaskPosture"]
