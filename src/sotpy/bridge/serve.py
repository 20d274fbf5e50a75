r"""``sotpy serve --zenoh FILE``: publish and subscribe the served graph's signals.

The file is TOML::

    wait = 60                          # s: wait for the peers before starting the loop

    [session]                          # Zenoh configuration keys (openSession's dict)
    mode = "peer"
    "listen/endpoints" = ["tcp/127.0.0.1:7447"]
    "scouting/multicast/enabled" = false

    [[publish]]                        # an output of the served graph -> a key
    signal = "talos_device.state"      # entity.signal
    key = "sotpy/talos/state"
    period = 1                         # every k-th tick (default 1)
    call = "after"                     # device.after (default: the state just written,
                                       # as SoT's RosPublish) or "before"

    [[subscribe]]                      # a key -> an input of the served graph
    signal = "talos_device.control"
    key = "sotpy/talos/control"
    type = "vector"                    # default: the input's type
    size = 38                          # optional: the shape every sample must have
    maxAge = 0.02                      # optional: s, older stops the loop safely
    sync = 1.0                         # optional: lock-step, wait up to 1 s per tick

Before the loop starts, the server waits (up to ``wait`` s) for a subscriber on every
published key, publishes once at the current tick (a peer that computes from the state
gets the first one), then waits for a first sample on every subscribed key, so that a
loop that needs them does not stop at its first tick. The publisher is the entity
``zenoh_pub``, the subscriber ``zenoh_sub`` (both in the served namespace).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from ..errors import BridgeError
from ..graph import plug, pool
from ..graph.signal import InputSignal, OutputSignal

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["ServeBridge", "loadServeConfig"]

_PUBLISH_KEYS = {"signal", "key", "period", "call"}
_SUBSCRIBE_KEYS = {"signal", "key", "type", "size", "maxAge", "sync"}


def loadServeConfig(path: str | Path) -> dict[str, Any]:
    """Read and check a ``--zenoh`` file (the module doc gives the format)."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            cfg = tomllib.load(f)
    except OSError as exc:
        raise BridgeError(f"cannot read the Zenoh bridge file {str(p)!r}: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise BridgeError(f"{p}: not valid TOML: {exc}") from None
    extra = set(cfg) - {"wait", "session", "publish", "subscribe"}
    if extra:
        raise BridgeError(
            f"{p}: unknown entries {sorted(extra)} (wait, session, publish, subscribe)"
        )
    wait = cfg.get("wait", 10.0)
    if isinstance(wait, bool) or not isinstance(wait, (int, float)) or wait < 0:
        raise BridgeError(f"{p}: wait is a number of seconds >= 0, got {wait!r}")
    for table, allowed in (("publish", _PUBLISH_KEYS), ("subscribe", _SUBSCRIBE_KEYS)):
        entries = cfg.get(table, [])
        if not isinstance(entries, list):
            raise BridgeError(f"{p}: {table} must be an array of tables ([[{table}]])")
        for i, e in enumerate(entries):
            where = f"{p}: {table}[{i}]"
            unknown = set(e) - allowed
            if unknown:
                raise BridgeError(f"{where}: unknown keys {sorted(unknown)} ({sorted(allowed)})")
            for need in ("signal", "key"):
                if not isinstance(e.get(need), str):
                    raise BridgeError(f"{where}: {need} (a string) is missing")
            if e.get("call", "after") not in ("before", "after"):
                raise BridgeError(f"{where}: call is 'before' or 'after', got {e['call']!r}")
    session = cfg.get("session")
    if session is not None and not isinstance(session, dict):
        raise BridgeError(f"{p}: session must be a table of Zenoh configuration keys")
    return {
        "wait": float(wait),
        "session": session,
        "publish": cfg.get("publish", []),
        "subscribe": cfg.get("subscribe", []),
        "path": str(p),
    }


class ServeBridge:
    """The publisher and subscriber a ``--zenoh`` file asks for, wired into the graph of
    ``device`` (its ``before``/``after`` lists trigger the publisher)."""

    def __init__(self, cfg: dict[str, Any], device: Any) -> None:
        from .entities import ZenohPublish, ZenohSubscribe

        self.cfg = cfg
        self.device = device
        self.pub: Any = None
        self.sub: Any = None
        try:
            if cfg["publish"]:
                self.pub = ZenohPublish("zenoh_pub", cfg["session"])
                calls: dict[tuple[str, int], None] = {}
                for i, e in enumerate(cfg["publish"]):
                    src = self._signal(e["signal"], OutputSignal, "an output", "publish", i)
                    name = f"p{i}_{src.shortName}".replace("-", "_")
                    self.pub.add(src.type.name, name, e["key"])
                    plug(src, self.pub.signal(name))
                    calls[(e.get("call", "after"), int(e.get("period", 1)))] = None
                if len(calls) > 1:
                    raise BridgeError(
                        f"{cfg['path']}: every [[publish]] entry must have the same call and "
                        "period (one publisher entity); got "
                        + ", ".join(f"{c} every {k}" for c, k in calls)
                    )
                (call, period), _ = calls.popitem()
                getattr(device, call).addSignal(self.pub.trigger, period)
            if cfg["subscribe"]:
                self.sub = ZenohSubscribe("zenoh_sub", cfg["session"])
                for i, e in enumerate(cfg["subscribe"]):
                    dst = self._signal(e["signal"], InputSignal, "an input", "subscribe", i)
                    name = f"s{i}_{dst.shortName}".replace("-", "_")
                    self.sub.add(e.get("type", dst.type.name), name, e["key"], e.get("size"))
                    if e.get("maxAge") is not None:
                        self.sub.setMaxAge(name, float(e["maxAge"]))
                    if e.get("sync") is not None:
                        self.sub.setSync(name, float(e["sync"]))
                    plug(self.sub.signal(name), dst)
        except BaseException:
            self.close()
            raise

    def _signal(self, path: str, kind: type, what: str, table: str, i: int) -> Any:
        try:
            sig = pool.getSignal(path)
        except Exception as exc:
            raise BridgeError(f"{self.cfg['path']}: {table}[{i}]: {exc}") from None
        if not isinstance(sig, kind):
            raise BridgeError(f"{self.cfg['path']}: {table}[{i}]: {sig.name} is not {what}")
        return sig

    def ready(self, say: Any = print) -> bool:
        """Wait for the peers (see the module doc); True when every key is served."""
        wait = self.cfg["wait"]
        ok = True
        if self.pub is not None:
            if not self.pub.waitForSubscribers(wait):
                say(f"sotpy serve: no subscriber on some published key after {wait:g} s")
                ok = False
            with pool.lock:
                self.pub.trigger(max(self.device.state.time, 0))
        if self.sub is not None:
            for name in self.sub.list():
                if not self.sub.wait(name, wait):
                    key = self.sub.stats()[name]["key"]
                    say(f"sotpy serve: no sample on {key!r} after {wait:g} s")
                    ok = False
        return ok

    def close(self) -> None:
        """Take the entities out of the graph and remove them (closing the Zenoh
        session): the publisher's trigger leaves the device's ``before``/``after``
        lists, the inputs the subscriber fed are unplugged (``pool.remove`` refuses an
        entity still in use)."""
        if self.pub is not None:
            for call in ("before", "after"):
                calls = getattr(self.device, call, None)
                if calls is not None:
                    calls.rmSignal(self.pub.trigger, missing_ok=True)
        if self.sub is not None:
            for sig in self.sub.signals():
                for d in list(sig._dependants):
                    if isinstance(d, InputSignal) and d.entity is not self.sub:
                        d.unplug()
        gone = [e for e in (self.pub, self.sub) if e is not None and pool.hasEntity(e.name)]
        if gone:
            pool.remove(*gone)
        self.pub = self.sub = None
