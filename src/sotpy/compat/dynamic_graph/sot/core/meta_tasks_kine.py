"""sot-core's ``meta_tasks_kine``: ``MetaTaskKine6d``, ``MetaTaskKineCom`` and ``gotoNd``,
served by sotpy (see :mod:`sotpy.compat._meta`)."""

from ...._meta import MetaTaskKine6d, MetaTaskKineCom, gotoNd

__all__ = ["MetaTaskKine6d", "MetaTaskKineCom", "gotoNd"]
