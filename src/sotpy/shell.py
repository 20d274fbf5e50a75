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

Completion (:class:`Completer`, the same in IPython, in the plain console and in
``sotpy connect``): inside the string argument of ``entity.signal("``,
``entity.hasSignal("``, ``pool.getEntity("`` / ``hasEntity("`` and after
``mapping["`` (``robot.tasks["``, ``robot.opPoints["``), Tab completes the names that
exist, dashed ones included (``right-wrist``, ``end-effector``), which Python's
completer cannot reach (it stops at the dash and offers keywords). A signal is offered
as ``com``, not as the call ``com(``: reading it is ``com.value``; calling it needs a
tick.
"""

from __future__ import annotations

import code
import re
import rlcompleter
import sys
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np

from .graph import plug, pool
from .graph.dot import writeGraph as _writeGraph
from .graph.signal import Signal
from .loop import ControlLoop, unlocked

__all__ = [
    "Completer",
    "LockedConsole",
    "interact",
    "ipythonMatcher",
    "ipythonShell",
    "makeNamespace",
    "stringCompletions",
]

# the text before the cursor ends inside a string literal, argument of one of these
_CALL = re.compile(
    r"(?P<obj>[A-Za-z_][\w.]*)\.(?P<method>signal|hasSignal|getEntity|hasEntity)\(\s*"
    r"(?P<quote>['\"])(?P<typed>[^'\"]*)$"
)
_KEY = re.compile(r"(?P<obj>[A-Za-z_][\w.]*)\[\s*(?P<quote>['\"])(?P<typed>[^'\"]*)$")


def _resolve(namespace: Mapping[str, Any], dotted: str) -> Any:
    """The object a dotted name denotes in ``namespace`` (attributes only, no call and
    no evaluation), or None."""
    head, *rest = dotted.split(".")
    if head not in namespace:
        return None
    obj = namespace[head]
    for attr in rest:
        try:
            obj = getattr(obj, attr)
        except Exception:  # a property that raises: no completion
            return None
    return obj


def stringCompletions(namespace: Mapping[str, Any], line: str) -> tuple[str, list[str]] | None:
    """Names for the string literal the text before the cursor (``line``) ends in.

    ``x.signal("..`` and ``x.hasSignal("..``: the names of entity ``x``'s signals (of
    every entity of the pool when ``x`` cannot be resolved without evaluating code);
    ``pool.getEntity("..`` and ``hasEntity``: the pool's entity names; ``x["..`` with
    ``x`` a mapping with string keys: its keys. Returns ``(typed, names)``: what is
    typed inside the quotes and the full names that start with it, sorted; None
    elsewhere.
    """
    m = _CALL.search(line)
    if m is not None:
        typed = m["typed"]
        if m["method"] in ("getEntity", "hasEntity"):
            names = [e.name for e in pool.entities()]
        else:
            obj = _resolve(namespace, m["obj"])
            if obj is not None and hasattr(obj, "signals") and hasattr(obj, "className"):
                names = [sig.shortName for sig in obj.signals()]
            else:
                names = sorted({sig.shortName for e in pool.entities() for sig in e.signals()})
        return typed, sorted(n for n in names if n.startswith(typed))
    m = _KEY.search(line)
    if m is not None:
        obj = _resolve(namespace, m["obj"])
        if isinstance(obj, Mapping):
            typed = m["typed"]
            keys = [k for k in obj if isinstance(k, str) and k.startswith(typed)]
            return typed, sorted(keys)
    return None


class Completer(rlcompleter.Completer):
    """Python's completer over ``namespace``, with the names of signals, entities and
    mapping keys inside string literals (:func:`stringCompletions`), and signals
    offered as names rather than calls.

    :meth:`completions` serves readline (the plain console, ``sotpy connect``), whose
    word stops at a dash: for ``dyn.signal("right-w`` readline's word is ``w``, and
    the matches are ``wrist``, the rest of ``right-wrist``."""

    def _callable_postfix(self, val: Any, word: str) -> str:
        if isinstance(val, Signal):  # read with .value; calling needs a tick
            return word
        return super()._callable_postfix(val, word)

    def completions(self, text: str, line: str | None = None) -> list[str]:
        """Completions of readline's word ``text``; ``line``: the text before the
        cursor (default ``text``)."""
        found = stringCompletions(self.namespace, text if line is None else line)
        if found is not None:
            typed, names = found
            cut = len(typed) - len(text)  # readline replaces its word only
            if cut < 0 or not typed.endswith(text):
                return names
            return [n[cut:] for n in names]
        out: list[str] = []
        for i in range(1000):
            m = self.complete(text, i)
            if m is None:
                break
            out.append(m)
        return out

    def readline(self, text: str, state: int) -> str | None:
        """A readline completer (``readline.set_completer(c.readline)``)."""
        if state == 0:
            import readline

            line = readline.get_line_buffer()[: readline.get_endidx()]
            self._found = self.completions(text, line)
        m = getattr(self, "_found", [])
        return m[state] if state < len(m) else None


def ipythonMatcher(namespace: Mapping[str, Any]) -> Any:
    """An IPython matcher (API v2, ``shell.Completer.custom_matchers``) completing the
    names of :func:`stringCompletions`; it hides IPython's other completions there."""
    from IPython.core.completer import SimpleCompletion, context_matcher

    @context_matcher()
    def sotpy_names(context: Any) -> dict[str, Any]:
        found = stringCompletions(namespace, context.text_until_cursor)
        if found is None or not found[1]:
            return {"completions": []}
        typed, names = found
        return {
            "completions": [SimpleCompletion(n, type="sotpy") for n in names],
            "matched_fragment": typed,
            "suppress": True,
        }

    return sotpy_names


def makeNamespace(
    robot: str | None = "talos",
    dt: float = 1e-3,
    cpus: Iterable[int] | None = None,
    spin: float | None = None,
) -> dict[str, Any]:
    """The namespace of the shell and of the remote interpreter.

    Args:
        robot: a shipped robot's name (``sotpy robots``) or a description path; None:
            no robot, no loop (the helpers raise until ``loop`` is set).
        dt: the loop's period and the device's time step, in s.
        cpus: the CPUs the loop's thread runs on (``ControlLoop(..., cpus=)``), or None.
        spin: the loop's ``spin`` (None: its default; ``dt``: its CPU never idles).
    """
    ns: dict[str, Any] = {"__name__": "__main__", "np": np, "pool": pool, "plug": plug}
    ns["unlocked"] = unlocked
    loop: ControlLoop | None = None
    if robot is not None:
        from .dynamics.robot import load_robot

        r = load_robot(robot)
        r.device.setControlType("velocity")
        r.device.control.value = np.zeros(r.model.nv)
        extra = {} if spin is None else {"spin": spin}
        loop = ControlLoop("loop", r.device, dt, cpus=cpus, **extra)
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


def ipythonShell(ns: dict[str, Any]) -> Any:
    """The IPython console of :func:`interact` (not started): each cell runs holding
    ``pool.lock``, our banner then IPython's own line, and the names of
    :func:`stringCompletions` offered by its completer. Raises ImportError without
    IPython."""
    from IPython.terminal.embed import InteractiveShellEmbed

    # IPython appends its own line (a tip) to banner1: end ours with a blank line
    shell = InteractiveShellEmbed(user_ns=ns, banner1=_banner(ns) + "\n\n")
    shell.Completer.custom_matchers.append(ipythonMatcher(ns))
    original: Callable[..., Any] = shell.run_cell

    def run_cell(*args: Any, **kwargs: Any) -> Any:
        with pool.lock:
            return original(*args, **kwargs)

    shell.run_cell = run_cell  # type: ignore[method-assign]
    return shell


def interact(ns: dict[str, Any], ipython: bool | None = None) -> None:
    """Run the console over ``ns`` (IPython if installed and ``ipython`` is not False)."""
    if ipython is not False:
        try:
            shell = ipythonShell(ns)
        except ImportError:
            if ipython:
                raise
        else:  # pragma: no cover - interactive
            shell()
            return
    try:
        import readline

        readline.set_completer(Completer(ns).readline)
        readline.parse_and_bind("tab: complete")
    except ImportError:  # pragma: no cover - Windows
        pass
    LockedConsole(ns).interact(banner=_banner(ns), exitmsg="")
