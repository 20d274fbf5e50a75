"""Run a SoT Python script unmodified: ``sotpy run script.py`` (or ``python -m
sotpy.compat script.py``).

The script's imports of ``dynamic_graph`` and its submodules (dynamic-graph-python,
sot-core, sot-dynamic-pinocchio, sot-talos, sot-tools, the dynamic-graph tutorial) are
served from sotpy by an import hook (:mod:`sotpy.compat._hook`) installed for the run
only: a plain ``import sotpy`` never installs it, so a real SoT installed beside sotpy
keeps its own ``dynamic_graph`` everywhere else. The modules are in
``sotpy.compat.dynamic_graph`` and in the table ``sotpy.compat._table``; their
names and what each maps to are in ``docs/porting.md``.

What sotpy does not provide raises :class:`UnsupportedFeature` (or
:class:`UnsupportedModule`, an ``ImportError``, for a module) naming the SoT feature and
sotpy's equivalent; nothing is silently ignored. At the end of the script the tracers
that still have files open are closed (their rows written), as a process exit closes a
SoT tracer's files.

::

    from sotpy.compat import run
    status = run("appli.py", ["--duration", "2"])    # the script's exit status
"""

from __future__ import annotations

import contextlib
import runpy
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path

from ._errors import UnsupportedFeature, UnsupportedModule, unsupported
from ._hook import SoTFinder, installed

__all__ = [
    "SoTFinder",
    "UnsupportedFeature",
    "UnsupportedModule",
    "active",
    "install",
    "installed",
    "main",
    "run",
    "uninstall",
    "unsupported",
]


def install() -> None:
    """Serve ``dynamic_graph`` from sotpy from now on (a ``SoTFinder`` first in
    ``sys.meta_path``). A ``dynamic_graph`` module already imported (a real SoT's) is
    set aside until :func:`uninstall`."""
    if installed():
        return
    saved = {n: m for n, m in sys.modules.items() if _ours(n) and not _served(m)}
    for n in saved:
        del sys.modules[n]
    _saved.update(saved)
    sys.meta_path.insert(0, SoTFinder())


def uninstall() -> None:
    """Stop serving ``dynamic_graph``: remove the finder and the module names it
    registered (the ``sotpy.compat`` modules stay), and restore the modules
    :func:`install` set aside."""
    sys.meta_path[:] = [f for f in sys.meta_path if not isinstance(f, SoTFinder)]
    for n in [n for n, m in sys.modules.items() if _ours(n) and _served(m)]:
        del sys.modules[n]
    sys.modules.update(_saved)
    _saved.clear()


_saved: dict[str, object] = {}


def _ours(name: str) -> bool:
    top = name.partition(".")[0]
    return top in ("dynamic_graph", "dynamic_graph_bridge")


def _served(module: object) -> bool:
    """Whether ``module`` came from the layer (a ``sotpy.compat`` module or one built
    from its table)."""
    name = getattr(module, "__name__", "")
    spec = getattr(module, "__spec__", None)
    loader = type(getattr(spec, "loader", None)).__module__
    return name.startswith("sotpy.compat.") or loader == "sotpy.compat._hook"


@contextlib.contextmanager
def active() -> Iterator[None]:
    """``with active(): ...``: the hook installed for the block (if it was not)."""
    was = installed()
    install()
    try:
        yield
    finally:
        if not was:
            uninstall()


def run(path: str | Path, argv: Sequence[str] = ()) -> int:
    """Run the SoT script ``path`` as ``__main__``, with ``sys.argv = [path, *argv]`` and
    the hook active; returns its exit status (0, or the code of its ``SystemExit``).

    An exception of the script propagates (the caller prints it). The script's directory
    is first in ``sys.path`` during the run, as for ``python script.py``; the tracers
    with files open are closed at the end.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"sotpy run: no such script: {path}")
    old_argv, old_path = sys.argv, list(sys.path)
    sys.argv = [str(path), *argv]
    sys.path.insert(0, str(path.resolve().parent))
    try:
        with active():
            try:
                runpy.run_path(str(path), run_name="__main__")
            except SystemExit as exc:
                code = exc.code
                if code is None:
                    return 0
                if isinstance(code, int):
                    return code
                print(code, file=sys.stderr)
                return 1
            finally:
                _closeTracers()
        return 0
    finally:
        sys.argv = old_argv
        sys.path[:] = old_path


def _closeTracers() -> None:
    """Close the files of every tracer of the pool that has some open."""
    from ..graph import Tracer, pool

    for e in pool.entities():
        if isinstance(e, Tracer) and e.files():
            e.close()


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m sotpy.compat script.py [args...]``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not args or args[0] in ("-h", "--help"):
        print("usage: python -m sotpy.compat SCRIPT.py [ARG ...]\n\n" + __doc__.split("\n\n")[1])
        return 0 if args else 2
    import traceback

    try:
        return run(args[0], args[1:])
    except FileNotFoundError as exc:
        print(exc, file=sys.stderr)
        return 2
    except Exception:
        traceback.print_exc()
        return 1
