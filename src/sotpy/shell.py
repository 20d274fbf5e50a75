"""``sotpy shell``: an interactive console over a robot's graph and its control loop.

::

    $ sotpy shell talos
    >>> stats()                 # the loop starts paused
    >>> step(10)                # ten ticks now
    >>> start(); stop()         # real time in the background
    >>> talos_device.state.value[:3]
    >>> writeGraph("graph.dot")

:func:`makeNamespace` builds what both the shell and ``sotpy serve`` offer: the robot
(:func:`sotpy.dynamics.robot.load_robot`), its device in velocity control holding still
(``control`` a zero constant), a :class:`~sotpy.loop.ControlLoop` ``loop`` (paused), every
entity of the pool under its name (when it is an identifier), ``pool``, ``plug``,
``unlocked`` and the helpers ``start()``, ``stop()``, ``step(n)``, ``stats()``,
``writeGraph(path)``.

The console is IPython when it is installed (``pip install sotpy[shell]``), else
Python's ``code.InteractiveConsole`` with ``rlcompleter`` tab completion (entities,
their signals and commands are attributes, so ``talos_device.<TAB>`` lists them). Each
input runs while holding :attr:`pool.lock <sotpy.graph.pool.Pool.lock>`: the loop
never ticks in the middle of an input. Before each prompt the console prints a loop
fault that happened since the last input.
"""

from __future__ import annotations

import code
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from .graph import plug, pool
from .graph.dot import writeGraph as _writeGraph
from .loop import ControlLoop, unlocked

__all__ = ["LockedConsole", "interact", "makeNamespace"]


def makeNamespace(robot: str | None = "talos", dt: float = 1e-3) -> dict[str, Any]:
    """The namespace of the shell and of the remote interpreter.

    Args:
        robot: a shipped robot's name (``sotpy robots``) or a description path; None:
            no robot, no loop (the helpers raise until ``loop`` is set).
        dt: the loop's period and the device's time step, in s.
    """
    ns: dict[str, Any] = {"__name__": "__main__", "np": np, "pool": pool, "plug": plug}
    ns["unlocked"] = unlocked
    loop: ControlLoop | None = None
    if robot is not None:
        from .dynamics.robot import load_robot

        r = load_robot(robot)
        r.device.setControlType("velocity")
        r.device.control.value = np.zeros(r.model.nv)
        loop = ControlLoop("loop", r.device, dt)
        ns["robot"] = r
    for e in pool.entities():
        if e.name.isidentifier():
            ns.setdefault(e.name, e)
    ns["loop"] = loop

    def _loop() -> ControlLoop:
        lp = ns.get("loop")
        if not isinstance(lp, ControlLoop):
            raise NameError("no control loop: set loop = ControlLoop('loop', device, dt)")
        return lp

    def start(ticks: int | None = None) -> None:
        """Start the loop in real time (in the background)."""
        _loop().start(ticks)

    def stop() -> None:
        """Stop the loop."""
        _loop().stop()

    def step(n: int = 1) -> None:
        """Run n ticks now, as fast as possible."""
        _loop().step(n)

    def stats() -> Any:
        """The loop's statistics (tick time, jitter, misses)."""
        return _loop().stats()

    def writeGraph(path: str = "graph.dot", **kwargs: Any) -> str:
        """Write the graph (dot, or svg/png/pdf rendered with Graphviz)."""
        return _writeGraph(path, **kwargs)

    for f in (start, stop, step, stats, writeGraph):
        ns[f.__name__] = f
    return ns


class LockedConsole(code.InteractiveConsole):
    """``code.InteractiveConsole`` running each input while holding ``pool.lock``, and
    printing a new loop fault before the next prompt."""

    def __init__(self, namespace: dict[str, Any]) -> None:
        super().__init__(namespace)
        self._seenFault: Any = None

    def runcode(self, code_obj: Any) -> None:
        with pool.lock:
            super().runcode(code_obj)
        self.reportFault()

    def reportFault(self) -> None:
        """Print the loop's pending fault once."""
        lp = self.locals.get("loop")
        fault = getattr(lp, "fault", None)
        if fault is not None and fault is not self._seenFault:
            self._seenFault = fault
            self.write(f"loop FAULT: {fault}\n")

    def raw_input(self, prompt: str = "") -> str:
        self.reportFault()
        return super().raw_input(prompt)


def _banner(ns: dict[str, Any]) -> str:
    names = sorted(k for k, v in ns.items() if hasattr(v, "className"))
    return (
        f"sotpy shell (Python {sys.version.split()[0]}). Entities: {', '.join(names)}.\n"
        "The loop is paused: step(n), start(), stop(), stats(), writeGraph(path). Each "
        "input runs between ticks."
    )


def interact(ns: dict[str, Any], ipython: bool | None = None) -> None:
    """Run the console over ``ns`` (IPython if installed and ``ipython`` is not False)."""
    banner = _banner(ns)
    if ipython is not False:
        try:
            from IPython.terminal.embed import InteractiveShellEmbed
        except ImportError:
            if ipython:
                raise
        else:  # pragma: no cover - IPython is optional
            shell = InteractiveShellEmbed(user_ns=ns, banner1=banner)
            original: Callable[..., Any] = shell.run_cell

            def run_cell(*args: Any, **kwargs: Any) -> Any:
                with pool.lock:
                    return original(*args, **kwargs)

            shell.run_cell = run_cell  # type: ignore[method-assign]
            shell()
            return
    try:
        import readline
        import rlcompleter

        readline.set_completer(rlcompleter.Completer(ns).complete)
        readline.parse_and_bind("tab: complete")
    except ImportError:  # pragma: no cover - Windows
        pass
    LockedConsole(ns).interact(banner=banner, exitmsg="")
