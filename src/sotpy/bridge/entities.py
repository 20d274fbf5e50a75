r"""``ZenohPublish`` and ``ZenohSubscribe``: signals across processes and machines.

The SoT's ROS bridge entities (``RosPublish``, ``RosSubscribe``) with the same commands,
over Eclipse Zenoh (``pip install 'sotpy[zenoh]'``)::

    pub = ZenohPublish("pub", config)             # config: see openSession
    pub.add("vector", "state", "talos/state")      # an input signal 'state' -> key
    plug(device.state, pub.state)
    device.after.addSignal(pub.trigger)            # the state just written, every tick

    sub = ZenohSubscribe("sub", config)
    sub.add("vector", "control", "talos/control", size=38)   # an output 'control'
    sub.setMaxAge("control", 0.005)                # older than 5 ms: the loop stops safely
    plug(sub.control, device.control)

Publishing
----------
Reading ``pub.trigger`` at tick ``t`` reads every input at ``t`` and sends one sample
per key (:mod:`sotpy.bridge.encoding`: header with the sample's number and ``t``, then
the value). ``setPeriod(k)`` sends every ``k``-th tick (so does
``device.after.addDownsampledSignal(pub.trigger, k)``, SoT's way). A value the encoding
refuses (a NaN) raises :class:`~sotpy.errors.BridgeError` from ``trigger``: nothing is
sent. The trigger checks and copies each value; a thread of the publisher, which looks
for them every ``SEND_POLL`` s, packs and puts the samples, in order, once the
tick's thread releases the interpreter (its next sleep or wait; ``setSendThread(False)``
packs and puts them at once, on the tick's thread), with congestion control DROP (never
blocked by the network) and ``express`` (no batching).
A process without a device ticks a publisher with ``ControlLoop("loop", pub, dt)``:
:meth:`ZenohPublish.increment` reads the trigger at the publisher's tick and moves it
on.

Subscribing
-----------
Each key's samples wait in a ring of :data:`RING` samples inside Zenoh (a reader that
falls behind loses the oldest, which are counted, instead of blocking the network). A
subscribed output read at tick ``t`` takes what arrived since its last read, decodes
and checks each sample in order, and holds the newest accepted one. Its ``time`` is the
tick at which that sample arrived (the first tick that read it). A compiled plan (a
control loop's tick) treats it as it treats a device's state: what reads it is
recomputed at every tick, by the same steps as in a single-process graph (the SOT's
fused rows); the lazy pull (a script, the shell) recomputes them only when a new sample
arrived. The tick thread does this work:
no Python callback thread competes with it for the interpreter.

A sample that the encoding refuses (malformed, wrong type, a size other than the
declared ``size``, over the size limit, a NaN) is counted by reason in ``stats()`` and
logged once per key and reason on the ``sotpy.bridge`` logger; the output keeps its
value. Without a declared ``size`` the first accepted vector or matrix fixes the shape.

Freshness
---------
The **age** of a subscribed output is the wall-clock time since the sample it holds
was taken from Zenoh (at the read that took it: within one tick of its arrival),
``age(signalName)``. With ``setMaxAge(signalName, s)``, a read at which the age exceeds
``s`` raises :class:`~sotpy.errors.StaleSignalError` naming the key and the age; a
read before the first sample raises it too. Plugged upstream of a device's control,
this stops the device safely through the control loop's fault path (the control is set
to a safe constant; see :mod:`sotpy.loop`) instead of reusing a stale value.

**Lock-step** (a simulation split across processes): ``setSync(signalName, timeout)``
makes a read at tick ``t`` wait, up to ``timeout`` s, for a sample whose tick is ``t``
or later. A device that publishes its state in ``device.after`` and waits for the
control of the same tick, and a controller that waits for the state of its tick, then
run tick by tick, each tick computing what the single-process graph computes. A wait
that times out raises :class:`~sotpy.errors.StaleSignalError`.

Sessions
--------
Entities created with the same configuration share one Zenoh session (opened by the
first, closed with the last or at interpreter exit). ``config`` is None (Zenoh's
defaults, or the file named by the ``ZENOH_CONFIG`` environment variable), a path to a
Zenoh JSON5 configuration file, a JSON5 string, or a dict of Zenoh configuration keys
to values (``{"mode": "peer", "connect/endpoints": ["tcp/192.168.1.10:7447"]}``);
:func:`loopbackConfig` makes one for one host.
"""

from __future__ import annotations

import atexit
import collections
import contextlib
import json
import logging
import math
import threading
import time
import weakref
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import BridgeError, SignalTypeError, StaleSignalError
from ..graph import BOOL, DOUBLE, INT, MATRIX, STRING, VECTOR, Entity, Output, Plan, command
from ..graph.pool import pool
from ..graph.signal import FORCE, InputSignal, OutputSignal
from ..graph.types import SignalType
from .encoding import MAX_SAMPLE_BYTES, SampleError, checked, decode, expectedShape, pack

__all__ = [
    "EXTRA",
    "RING",
    "ZenohPublish",
    "ZenohSubscribe",
    "loopbackConfig",
    "openSession",
    "zenohAvailable",
]

log = logging.getLogger("sotpy.bridge")

#: How to install the optional dependency (named in the error raised without it).
EXTRA = "pip install 'sotpy[zenoh]'"
#: Samples kept per subscribed key between two reads (the oldest are dropped beyond).
RING = 64
# A lock-step wait polls between sleeps of this many s (a sleep lasts 60-110 us on Linux
# with its default timer slack): a spin with sleep(0) took a core from the processes it
# waits for on a 2-core machine (bench_zenoh: trigger p50 54 us spinning)
_WAIT_SLEEP = 10e-6

# SoT's type names (RosSubscribe's 'matrixHomo', 'unsigned') and sotpy's
_TYPE_ALIASES = {"matrixHomo": "SE3", "unsigned": "int"}


def _zenoh() -> Any:
    try:
        import zenoh
    except ImportError:
        raise BridgeError(
            f"the Zenoh bridge needs the eclipse-zenoh package: {EXTRA} "
            "(or pip install eclipse-zenoh)"
        ) from None
    return zenoh


def zenohAvailable() -> bool:
    """Whether the ``eclipse-zenoh`` package can be imported."""
    try:
        _zenoh()
    except BridgeError:
        return False
    return True


def _signal_type(typeName: str, who: str) -> tuple[str, SignalType]:
    name = _TYPE_ALIASES.get(typeName, typeName)
    if name == "SE3":
        from ..dynamics.types import SE3

        return name, SE3
    types = {
        "double": DOUBLE,
        "int": INT,
        "bool": BOOL,
        "vector": VECTOR,
        "matrix": MATRIX,
        "string": STRING,
    }
    if name not in types:
        raise BridgeError(
            f"{who}: unknown type {typeName!r}; expected one of double, int, bool, vector, "
            "matrix, SE3, string (or SoT's matrixHomo, unsigned)"
        )
    return name, types[name]


# -- sessions ---------------------------------------------------------------------------
def loopbackConfig(
    listen: list[str] | None = None, connect: list[str] | None = None
) -> dict[str, Any]:
    """A peer configuration for one host: no multicast scouting, listen on and connect
    to the given endpoints (``"tcp/127.0.0.1:7447"``); one side listens, the other
    connects."""
    return {
        "mode": "peer",
        "scouting/multicast/enabled": False,
        "listen/endpoints": list(listen or []),
        "connect/endpoints": list(connect or []),
    }


def _make_config(config: Any) -> tuple[str, Any]:
    """(canonical text, zenoh.Config) of a configuration given as openSession takes it."""
    import os

    zenoh = _zenoh()
    try:
        if config is None:
            if os.environ.get("ZENOH_CONFIG"):
                return f"env:{os.environ['ZENOH_CONFIG']}", zenoh.Config.from_env()
            return "default", zenoh.Config()
        if isinstance(config, zenoh.Config):
            return f"config:{config}", config
        if isinstance(config, Mapping):
            cfg = zenoh.Config()
            for key, value in config.items():
                cfg.insert_json5(str(key), json.dumps(value))
            return "dict:" + json.dumps(config, sort_keys=True, default=str), cfg
        if isinstance(config, (str, Path)):
            text = str(config)
            if text.lstrip().startswith("{"):
                return f"json5:{text}", zenoh.Config.from_json5(text)
            path = Path(text).expanduser().resolve()
            if not path.is_file():
                raise BridgeError(f"Zenoh configuration file {text!r} not found")
            return f"file:{path}", zenoh.Config.from_file(str(path))
    except zenoh.ZError as exc:
        raise BridgeError(f"Zenoh refused the configuration {config!r}: {exc}") from None
    raise BridgeError(
        "a Zenoh configuration is None, a file path, a JSON5 string, a dict of keys to "
        f"values or a zenoh.Config; got {type(config).__name__}"
    )


class _Sessions:
    """Zenoh sessions shared by the entities of one configuration, reference counted."""

    def __init__(self) -> None:
        self._open: dict[str, list[Any]] = {}  # canonical config -> [session, refs]
        self._lock = threading.Lock()

    def acquire(self, config: Any) -> tuple[str, Any]:
        text, cfg = _make_config(config)
        with self._lock:
            entry = self._open.get(text)
            if entry is None:
                try:
                    session = _zenoh().open(cfg)
                except Exception as exc:
                    raise BridgeError(f"cannot open a Zenoh session: {exc}") from None
                entry = self._open[text] = [session, 0]
            entry[1] += 1
            return text, entry[0]

    def release(self, text: str) -> None:
        with self._lock:
            entry = self._open.get(text)
            if entry is None:
                return
            entry[1] -= 1
            if entry[1] <= 0:
                del self._open[text]
                _close(entry[0])

    def closeAll(self) -> None:
        with self._lock:
            entries, self._open = list(self._open.values()), {}
        for session, _ in entries:
            _close(session)


def _close(session: Any) -> None:
    try:
        session.close()
    except Exception:  # pragma: no cover - closing at exit must not raise
        log.exception("closing a Zenoh session failed")


_sessions = _Sessions()
_senders: weakref.WeakSet[Any] = weakref.WeakSet()


def _at_exit() -> None:
    # what is queued goes out first; then the sessions close (a process that exits with
    # a Zenoh session open hangs in the interpreter's teardown)
    for sender in list(_senders):
        sender.close()
    _sessions.closeAll()


atexit.register(_at_exit)


def openSession(config: Any = None) -> Any:
    """The Zenoh session of ``config`` (see the module doc) that the entities of the same
    configuration share, opened if none is; a session opened here stays open until the
    interpreter exits. For raw ``put`` and ``declare_*`` calls beside the entities."""
    return _sessions.acquire(config)[1]


class _BridgeEntity(Entity):
    """What publishers and subscribers share: the session and the key table."""

    def __init__(self, name: str, config: Any = None) -> None:
        self._keys: dict[str, Any] = {}
        self._sessionKey: str | None = None
        self._sessionKey, self._session = _sessions.acquire(config)

    def _who(self, cmd: str) -> str:
        return f"{self.className}({self.name}).{cmd}"

    def _entry(self, cmd: str, signalName: str) -> Any:
        k = self._keys.get(signalName)
        if k is None:
            known = ", ".join(self._keys) or "none"
            raise BridgeError(f"{self._who(cmd)}: no key for signal {signalName!r} (keys: {known})")
        return k

    def _checkNew(self, cmd: str, typeName: str, signalName: str, key: str) -> None:
        if not isinstance(signalName, str) or not signalName.isidentifier():
            raise BridgeError(
                f"{self._who(cmd)}: the signal name must be an identifier, got {signalName!r}"
            )
        if self.hasSignal(signalName) or signalName in self._keys:
            raise BridgeError(f"{self._who(cmd)}: a signal named {signalName!r} already exists")
        if not isinstance(key, str) or not key or key.startswith("/") or key.endswith("/"):
            raise BridgeError(
                f"{self._who(cmd)}: {key!r} is not a Zenoh key expression (a/b/c, no leading "
                "or trailing slash)"
            )

    @command
    def list(self) -> list[str]:
        """The signal names of the keys, in the order they were added."""
        return list(self._keys)

    @command
    def clear(self) -> None:
        """Remove every key (rm each)."""
        for name in list(self._keys):
            self.rm(name)

    def rm(self, signalName: str) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def onRemove(self) -> None:
        sender = self.__dict__.get("_sender")
        if sender is not None:
            sender.close()
        if "_keys" in self.__dict__:
            for k in self._keys.values():
                k.undeclare()
            self._keys = {}
        text = self.__dict__.get("_sessionKey")
        if text is not None:
            self._sessionKey = None
            _sessions.release(text)


# -- publishing -------------------------------------------------------------------------
def _put(key: Any, data: bytes) -> None:
    """Zenoh's put of one sample, in shared memory when the key asks for it."""
    if key.shm is not None:
        buf = key.shm.alloc(len(data))
        buf[:] = data
        key.pub.put(buf)
    else:
        key.pub.put(data)


#: how often a publisher's send thread looks for queued samples (s)
SEND_POLL = 2e-4
#: ... and after 10 ms without any (a publisher nobody ticks: a shell, a paused loop)
SEND_IDLE_POLL = 5e-3
_IDLE_AFTER = round(1e-2 / SEND_POLL)


class _Sender:
    """Packs and puts the samples a publisher's trigger checked, in order, from a thread
    of its own that looks for them every ``SEND_POLL`` seconds.

    The tick's thread only checks each value and copies it (:func:`.encoding.checked`)
    and queues it: nothing wakes this thread, which sleeps (the interpreter released)
    and, when it wakes, gets the interpreter once the tick's thread sleeps in its turn.
    After 10 ms with nothing queued it looks every ``SEND_IDLE_POLL`` (5 ms) instead,
    until a sample comes: an idle publisher costs next to nothing, and the first
    sample after a pause waits up to 5 ms.
    Measured in the tick's thread (bench_zenoh's publisher of a 38-vector after each
    Talos reach tick at 1 kHz, thread CPU time, quiet 2-core machine): the graph's
    evaluation of the trigger 2 to 3 us, the check and copy about 10 us cold (2 us hot),
    the packing 8 us, and a wake-up of this thread per tick 12 us with a pipe, 23 us
    with a ``threading.Event`` (the system call and the other core's wake-up count in
    the caller's CPU time); the poll costs none of these. A put on the tick's thread
    (``setSendThread(False)``) pays the packing and the put's system call there instead
    (it wakes the subscriber's process, which can take the core), and saves up to
    ``SEND_POLL`` of latency.
    """

    def __init__(self, who: str) -> None:
        self._who = who
        self._items: collections.deque[tuple[Any, int, Any, int, int]] = collections.deque()
        #: queue((key, code, payload, seq, tick)): a sample for the thread to pack and put
        self.queue = self._items.append
        self._closed = False
        self._failed: set[str] = set()
        self._thread = threading.Thread(target=self._run, name=f"{who} sender", daemon=True)
        self._thread.start()
        _senders.add(self)

    def _run(self) -> None:
        idle = 0  # looks that found nothing, in a row
        while not self._closed:
            time.sleep(SEND_POLL if idle < _IDLE_AFTER else SEND_IDLE_POLL)
            if self._items:
                idle = 0
                self._drain()
            else:
                idle += 1

    def _drain(self) -> None:
        items = self._items
        while items:
            key, code, payload, seq, tick = items.popleft()
            try:
                _put(key, pack(code, payload, seq, tick))
            except Exception as exc:  # the session closed, Zenoh refused: say it once
                if key.key not in self._failed:
                    self._failed.add(key.key)
                    log.error("%s: put on %r failed: %s", self._who, key.key, exc)

    def close(self) -> None:
        """Put what is queued, then stop the thread."""
        if self._closed:
            return
        self._closed = True
        if self._thread is not threading.current_thread():
            self._thread.join(2.0)
        self._drain()
        _senders.discard(self)


class _PubKey:
    __slots__ = ("key", "name", "pub", "sent", "seq", "shape", "shm", "typeName")

    def __init__(self, name: str, typeName: str, key: str, pub: Any, shape: Any) -> None:
        self.name, self.typeName, self.key, self.pub, self.shape = name, typeName, key, pub, shape
        self.seq = 0
        self.sent = 0
        self.shm: Any = None

    def undeclare(self) -> None:
        with contextlib.suppress(Exception):  # the session may be closed already
            self.pub.undeclare()


class ZenohPublish(_BridgeEntity):
    """Publish input signals on Zenoh keys, one sample per key each time ``trigger`` is
    read (SoT's ``RosPublish``); see :mod:`sotpy.bridge.entities`.

    ``ZenohPublish(name, config=None)``: ``config`` the Zenoh session's configuration
    (see :func:`openSession`).
    """

    @Output(INT, withTime=True, timeDependent=True, doc="number of samples sent")
    def trigger(self, t: int, *values: Any) -> int:
        """Reads every input at t and sends one sample per key."""
        sender = self._sender
        queue = None if sender is None else sender.queue
        for k, v in zip(self._order, values, strict=True):
            try:
                code, payload = checked(k.typeName, v, k.shape)
            except SampleError as exc:
                raise BridgeError(
                    f"{self.className}({self.name})::input({k.typeName})::{k.name}: not sent "
                    f"on {k.key!r} at tick {t}: {exc}"
                ) from None
            if queue is None:
                _put(k, pack(code, payload, k.seq, t))
            else:
                queue((k, code, payload, k.seq, t))
            k.seq += 1
            k.sent += 1
            self._sent += 1
        return self._sent

    def __init__(self, name: str, config: Any = None) -> None:
        super().__init__(name, config)
        self._order: list[_PubKey] = []
        self._sent = 0
        self._sender: _Sender | None = _Sender(f"{self.className}({name})")
        self._shm: Any = None  # the shared-memory provider (setSharedMemory), or None
        self._tick = max(pool.time, 0)
        self._plan = Plan([self.trigger])

    @command
    def add(self, type: str, signalName: str, key: str, size: Any = None) -> None:
        """Publish a new input signal signalName of type type on the key expression key

        type: double, int, bool, vector, matrix, SE3 or string (SoT's matrixHomo and
        unsigned are accepted); size: the shape every sample must have (n for a vector,
        (rows, cols) for a matrix), None for any.
        """
        who = self._who("add")
        typeName, stype = _signal_type(type, who)
        self._checkNew("add", typeName, signalName, key)
        shape = expectedShape(typeName, size)
        try:
            pub = self._session.declare_publisher(
                key,
                congestion_control=_zenoh().CongestionControl.DROP,
                express=True,
            )
        except Exception as exc:
            raise BridgeError(f"{who}: Zenoh refused the key {key!r}: {exc}") from None
        sig = InputSignal(self, signalName, stype, doc=f"published on {key}")
        self.addSignal(sig)
        k = _PubKey(signalName, typeName, key, pub, shape)
        k.shm = self._shm
        self._keys[signalName] = k
        self._order.append(k)
        self.trigger.setDependencies([*self.trigger.dependencies, sig])

    @command
    def rm(self, signalName: str) -> None:
        """Stop publishing signalName and remove its input signal."""
        k = self._entry("rm", signalName)
        self._order = [o for o in self._order if o is not k]
        self.trigger.setDependencies([self.signal(o.name) for o in self._order])
        del self._keys[signalName]
        self.removeSignal(signalName)
        k.undeclare()

    @command
    def setPeriod(self, k: int) -> None:
        """Send every k-th tick (trigger's period; 1: every tick)."""
        self.trigger.setPeriod(k)

    @command
    def setSharedMemory(self, enabled: bool) -> None:
        """Put the samples of every key in shared memory (Zenoh's SHM, same host only; a
        peer on another host receives a copy), or in ordinary buffers (the default)."""
        self._shm = None
        if enabled:
            try:
                from zenoh import shm
            except ImportError as exc:
                raise BridgeError(
                    f"{self._who('setSharedMemory')}: this eclipse-zenoh has no shared memory "
                    f"({exc})"
                ) from None
            self._shm = shm.ShmProvider.default_backend(4 << 20)
        for k in self._order:
            k.shm = self._shm

    @command
    def setSendThread(self, enabled: bool) -> None:
        """Put the samples from a thread of the publisher (default), or on the tick's

        With the thread, a trigger only checks, copies and queues (a few us per key) and
        the samples leave within ``SEND_POLL`` s (0.2 ms; 5 ms after a pause of 10 ms),
        once the tick's thread sleeps or waits; without it, each put (a system call,
        which may let the subscriber's process take the core) runs in the tick, and the
        samples leave at once (lower latency, a longer tick). See docs/zenoh.md, "What
        it costs".
        """
        if enabled and self._sender is None:
            self._sender = _Sender(f"{self.className}({self.name})")
        elif not enabled and self._sender is not None:
            self._sender.close()
            self._sender = None

    @command
    def waitForSubscribers(self, timeout: float = 10.0) -> bool:
        """Wait until every key has a matching subscriber (or timeout s); True if so

        Zenoh drops what is put before a subscriber is known: call this before the first
        sample that matters (the start of a lock-step run).
        """
        deadline = time.monotonic() + timeout
        while True:
            if all(k.pub.matching_status.matching for k in self._order):
                return True
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)

    @command
    def stats(self) -> dict[str, dict[str, Any]]:
        """Per signal: key, type, samples sent, next sequence number."""
        return {
            k.name: {"key": k.key, "type": k.typeName, "sent": k.sent, "seq": k.seq}
            for k in self._order
        }

    @command
    def increment(self, dt: float) -> None:
        """Read trigger at the publisher's tick, then move the tick on (dt unused)

        So a process without a device ticks a publisher with ControlLoop(name, pub, dt):
        each tick reads its inputs (pulling the graph) and sends them.
        """
        t = self._tick
        self._plan.run(t)
        self._tick = t + 1

    @command
    def getTime(self) -> int:
        """The tick the next increment reads the inputs at."""
        return self._tick

    @command
    def setTime(self, t: int) -> None:
        """Set the tick of the next increment (align with the peer's ticks)."""
        self._tick = int(t)


# -- subscribing ------------------------------------------------------------------------
class _SubKey:
    __slots__ = (
        "arrivalNs",
        "arrivalTick",
        "first",
        "key",
        "latch",
        "limit",
        "lost",
        "maxAge",
        "name",
        "received",
        "refused",
        "reordered",
        "seq",
        "shape",
        "sub",
        "sync",
        "tick",
        "typeName",
        "warned",
    )

    def __init__(self, name: str, typeName: str, key: str, sub: Any, shape: Any) -> None:
        self.name, self.typeName, self.key, self.sub = name, typeName, key, sub
        self.shape = shape
        self.latch = shape is None and typeName in ("vector", "matrix")
        self.limit = MAX_SAMPLE_BYTES
        self.maxAge: float | None = None
        self.sync: float | None = None
        self.seq = -1  # of the sample held (-1: none yet)
        self.tick = -1  # the publisher's tick of the sample held
        self.arrivalTick = -1
        self.arrivalNs = 0
        self.first = True
        self.received = 0
        self.refused: dict[str, int] = {}
        self.lost = 0
        self.reordered = 0
        self.warned: set[str] = set()

    def undeclare(self) -> None:
        with contextlib.suppress(Exception):  # the session may be closed already
            self.sub.undeclare()

    def age(self, now_ns: int | None = None) -> float:
        if self.first:
            return math.inf
        now = time.perf_counter_ns() if now_ns is None else now_ns
        return (now - self.arrivalNs) * 1e-9


class _SubscribedSignal(OutputSignal):
    """The output of a subscribed key: each read takes the newest accepted sample (its
    ``time`` is the tick it arrived at) and checks the age limit and the lock-step."""

    __slots__ = ("_key",)

    def _update(self, t: int) -> None:
        k = self._key
        now = self.entity._poll(self, k, t)
        if k.sync is not None and k.tick < t:
            now = self.entity._waitTick(self, k, t)
        if k.first:
            raise StaleSignalError(
                f"{self.name}: no sample received yet on key {k.key!r} (tick {t})",
                k.key,
                math.inf,
            )
        if k.maxAge is not None:
            age = (now - k.arrivalNs) * 1e-9
            if age > k.maxAge:
                raise StaleSignalError(
                    f"{self.name}: the last sample on key {k.key!r} is {age * 1e3:.1f} ms old "
                    f"at tick {t}, limit {k.maxAge * 1e3:g} ms (arrived at tick "
                    f"{k.arrivalTick}): the publisher stopped or the link is down",
                    k.key,
                    age,
                )
        self._checked = t
        if self._invalid == FORCE:
            self._invalid = t


class ZenohSubscribe(_BridgeEntity):
    """Expose Zenoh keys as output signals (SoT's ``RosSubscribe``), each with its age
    and an optional age limit; see :mod:`sotpy.bridge.entities`.

    ``ZenohSubscribe(name, config=None)``: ``config`` the Zenoh session's configuration
    (see :func:`openSession`).
    """

    @command
    def add(self, type: str, signalName: str, key: str, size: Any = None) -> None:
        """Subscribe to the key expression key as a new output signal signalName

        type: double, int, bool, vector, matrix, SE3 or string (SoT's matrixHomo and
        unsigned are accepted); size: the shape every sample must have (n for a vector,
        (rows, cols) for a matrix); None: the first accepted sample fixes it.
        """
        who = self._who("add")
        typeName, stype = _signal_type(type, who)
        self._checkNew("add", typeName, signalName, key)
        shape = expectedShape(typeName, size)
        zenoh = _zenoh()
        try:
            sub = self._session.declare_subscriber(key, zenoh.handlers.RingChannel(RING))
        except Exception as exc:
            raise BridgeError(f"{who}: Zenoh refused the key {key!r}: {exc}") from None
        k = _SubKey(signalName, typeName, key, sub, shape)
        sig = _SubscribedSignal(
            self,
            signalName,
            stype,
            _never_called,
            timeDependent=False,
            doc=f"subscribed from {key}; time: the tick the sample arrived at",
        )
        sig._key = k
        # a compiled plan treats it as a device's state: what reads it is live (computed
        # every tick, the SOT's fused rows included), as in a single-process graph
        sig._volatile = True
        self.addSignal(sig)
        self._keys[signalName] = k

    @command
    def rm(self, signalName: str) -> None:
        """Stop subscribing signalName and remove its output signal."""
        k = self._entry("rm", signalName)
        del self._keys[signalName]
        self.removeSignal(signalName)
        k.undeclare()

    @command
    def setMaxAge(self, signalName: str, seconds: float | None) -> None:
        """Reading signalName with a sample older than seconds (or none) raises

        StaleSignalError (a control loop then stops the device safely); None: no limit.
        """
        k = self._entry("setMaxAge", signalName)
        if seconds is not None and not (isinstance(seconds, (int, float)) and seconds > 0):
            raise BridgeError(
                f"{self._who('setMaxAge')}: the age limit is a number of seconds > 0 or None, "
                f"got {seconds!r}"
            )
        k.maxAge = None if seconds is None else float(seconds)

    @command
    def setSync(self, signalName: str, timeout: float | None) -> None:
        """Lock-step: a read at tick t waits up to timeout s for a sample of tick >= t

        None: no wait (the newest sample, whatever its tick). A wait that times out
        raises StaleSignalError.
        """
        k = self._entry("setSync", signalName)
        if timeout is not None and not (isinstance(timeout, (int, float)) and timeout > 0):
            raise BridgeError(
                f"{self._who('setSync')}: the timeout is a number of seconds > 0 or None, "
                f"got {timeout!r}"
            )
        k.sync = None if timeout is None else float(timeout)

    @command
    def setSizeLimit(self, signalName: str, nbytes: int) -> None:
        """Refuse samples of signalName larger than nbytes (default 1 MiB)."""
        k = self._entry("setSizeLimit", signalName)
        if isinstance(nbytes, bool) or not isinstance(nbytes, int) or nbytes < 25:
            raise BridgeError(
                f"{self._who('setSizeLimit')}: expected a number of bytes >= 25, got {nbytes!r}"
            )
        k.limit = nbytes

    @command
    def age(self, signalName: str) -> float:
        """Seconds since the sample signalName holds arrived (inf: none yet)."""
        return self._entry("age", signalName).age()

    @command
    def arrivalTick(self, signalName: str) -> int:
        """The tick at which the sample signalName holds arrived (-1: none yet)."""
        return self._entry("arrivalTick", signalName).arrivalTick

    @command
    def stats(self) -> dict[str, dict[str, Any]]:
        """Per signal: key, type, received, accepted (seq of the last), refused by reason,
        lost (gaps in the numbers), reordered, age (s), arrival tick, sender's tick."""
        out = {}
        for name, k in self._keys.items():
            out[name] = {
                "key": k.key,
                "type": k.typeName,
                "received": k.received,
                "refused": dict(k.refused),
                "lost": k.lost,
                "reordered": k.reordered,
                "seq": k.seq,
                "age": k.age(),
                "arrivalTick": k.arrivalTick,
                "senderTick": k.tick,
                "maxAge": k.maxAge,
                "sync": k.sync,
            }
        return out

    @command
    def wait(self, signalName: str, timeout: float = 10.0) -> bool:
        """Wait for a first sample on signalName (up to timeout s); True if one came

        Reads the signal at the current tick (holding pool.lock for each read), so call
        it before the loop starts.
        """
        sig = self.signal(signalName)
        k = self._entry("wait", signalName)
        deadline = time.monotonic() + timeout
        while True:
            with pool.lock:
                self._poll(sig, k, max(pool.time, 0))
                if not k.first:
                    return True
            if time.monotonic() > deadline:
                return False
            time.sleep(0.002)

    # -- the tick path ---------------------------------------------------------------
    def _poll(self, sig: _SubscribedSignal, k: _SubKey, t: int) -> int:
        """Take what arrived on ``k``: hold the newest accepted sample (stamped ``t``);
        returns the clock (perf_counter_ns) of the poll."""
        recv = k.sub.try_recv
        newest = None
        while True:
            s = recv()
            if s is None:
                break
            k.received += 1
            try:
                seq, tick, value = decode(s.payload.to_bytes(), k.typeName, k.shape, k.limit)
            except SampleError as exc:
                self._refuse(k, exc)
                continue
            last = newest[0] if newest is not None else k.seq
            if last >= 0:
                if seq <= last:
                    k.reordered += 1  # an older number: a restarted publisher, or two
                else:
                    k.lost += seq - last - 1
            newest = (seq, tick, value)
            if k.latch:
                k.shape = value.shape
                k.latch = False
        now = time.perf_counter_ns()
        if newest is not None:
            k.seq, k.tick, value = newest
            k.first = False
            k.arrivalNs = now
            k.arrivalTick = t
            sig._value = value
            sig._time = t
        return now

    def _waitTick(self, sig: _SubscribedSignal, k: _SubKey, t: int) -> int:
        start = time.perf_counter_ns()
        deadline = start + int(k.sync * 1e9)  # type: ignore[operator]
        while True:
            now = self._poll(sig, k, t)
            if k.tick >= t:
                return now
            if now > deadline:
                raise StaleSignalError(
                    f"{sig.name}: no sample of tick {t} on key {k.key!r} within "
                    f"{k.sync:g} s (lock-step; the last was of tick {k.tick}): the peer "
                    "stopped or is too slow",
                    k.key,
                    k.age(now),
                )
            time.sleep(_WAIT_SLEEP)

    def _refuse(self, k: _SubKey, exc: SampleError) -> None:
        k.refused[exc.reason] = k.refused.get(exc.reason, 0) + 1
        if exc.reason not in k.warned:
            k.warned.add(exc.reason)
            log.warning(
                "%s: refused a sample on key %r (%s); further %s refusals are counted in "
                "stats() without a message",
                f"{self.className}({self.name})::{k.name}",
                k.key,
                exc,
                exc.reason,
            )


def _never_called(*args: Any) -> Any:  # pragma: no cover - _SubscribedSignal._update reads
    raise SignalTypeError("a subscribed signal is computed by its entity")
