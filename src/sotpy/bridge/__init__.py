"""Signals across processes and machines: SoT's ROS bridge entities over Eclipse Zenoh.

:class:`~sotpy.bridge.entities.ZenohPublish` and
:class:`~sotpy.bridge.entities.ZenohSubscribe` (``add(type, signalName, key)``,
``rm``, ``list``, ``clear``, as ``RosPublish`` and ``RosSubscribe``) carry signal values
in the versioned binary encoding of :mod:`sotpy.bridge.encoding`; a subscribed signal
reports its age and stops a control loop safely when it is older than its limit. The
encoding needs only numpy; the entities need the optional ``eclipse-zenoh`` package
(``pip install 'sotpy[zenoh]'``) and raise :class:`~sotpy.errors.BridgeError` naming
it when it is missing. See ``docs/zenoh.md``.
"""

from .encoding import SampleError, decode, decodeJointState, encode, encodeJointState
from .entities import (
    EXTRA,
    ZenohPublish,
    ZenohSubscribe,
    loopbackConfig,
    openSession,
    zenohAvailable,
)

__all__ = [
    "EXTRA",
    "SampleError",
    "ZenohPublish",
    "ZenohSubscribe",
    "decode",
    "decodeJointState",
    "encode",
    "encodeJointState",
    "loopbackConfig",
    "openSession",
    "zenohAvailable",
]
