"""sot-core's ``meta_tasks``: ``MetaTaskCom``, ``setGain``, ``generic6dReference``,
``goto6d`` and ``gotoNd``, served by sotpy (see :mod:`sotpy.compat._meta`)."""

from ...._meta import MetaTaskCom, generic6dReference, goto6d, gotoNd, setGain

__all__ = ["MetaTaskCom", "generic6dReference", "goto6d", "gotoNd", "setGain"]
