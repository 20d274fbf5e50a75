"""Sphinx configuration: sotpy's documentation site.

Build (from the repository root; ``-n -W`` make a broken reference fail the build)::

    python -m sphinx -W --keep-going -n -b html docs docs/_build/html

The Markdown pages (tutorials, references) are read by myst-parser; the API reference
(``docs/api/*.rst``) is generated from the docstrings by autodoc, with napoleon for the
Google-style ``Args:`` / ``Returns:`` sections. Everything works offline: there is no
intersphinx, so references to numpy, Pinocchio and the standard library are listed in
``nitpick_ignore_regex`` below instead of being linked.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "src"))  # document the checkout, installed or not

project = "sotpy"
author = "the sotpy developers"
copyright = "sotpy developers"

from sotpy import __version__ as release  # noqa: E402

version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]

# Markdown: `#` anchors for headings, so that links such as graph.md#writegraph resolve.
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

# autodoc: members in source order, signatures with their type hints.
autodoc_default_options = {
    "members": True,
    "member-order": "bysource",
    "show-inheritance": True,
}
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autoclass_content = "both"
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False

nitpicky = True
# Targets outside sotpy: no intersphinx (offline builds), so they are not linked.
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|pinocchio|pin|scipy|meshcat|proxsuite|daqp|matplotlib)(\..*)?"),
    (r"py:.*", r"(typing|collections|threading|socket|socketserver|code|pathlib|os|io)\..*"),
    (r"py:.*", r"(argparse|logging|subprocess|types|enum|dataclasses|abc|json)\..*"),
    (r"py:.*", r"rlcompleter\..*"),  # the base of sotpy.shell.Completer
    (r"py:class", r"(\w+\.)*(Path|Callable|Iterable|Iterator|Sequence|Mapping|Any|ndarray)"),
    (r"py:class", r"(\w+\.)*(ClassVar|Literal|TextIO|Self)"),  # Sphinx 7 qualifies them
    (r"py:class", r"_thread\..*"),
    # Private base classes (``_MetaTask``, ``_Adder``...) appear in "Bases:" lines; they
    # are implementation details, documented through their public subclasses.
    (r"py:.*", r"sotpy(\.\w+)*\._\w+"),
]

# Built-in names in type hints (``list[str]``, ``dict``) must not be resolved by
# Sphinx's fuzzy search to a sotpy method of the same name (``SOT.list``,
# ``TaskAbstract.list``): search them exactly, so that they stay plain text.
_BUILTINS = {"list", "dict", "tuple", "set", "frozenset", "str", "int", "float", "bool"}
_BUILTINS |= {"bytes", "object", "type", "complex", "range", "slice", "None"}


def _lookup(path: str):
    """The object a dotted path names (``sotpy.graph.Entity.plug``), or None."""
    import importlib

    parts = path.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        owner = None
        for name in parts[i:]:
            owner = obj
            if not hasattr(obj, name):
                return None
            obj = getattr(obj, name)
        return obj, owner, parts[-1]
    return None


def _canonical(path: str) -> list[str]:
    """Where the object that ``path`` names is defined: the names autodoc may document
    it by, most likely first.

    ``sotpy.graph.writeGraph`` -> ``sotpy.graph.dot.writeGraph``;
    ``sotpy.graph.tracer.Tracer.displaySignals`` -> ``sotpy.graph.entity.Entity.displaySignals``
    (a method found in a base class); ``sotpy.loop.pool.lock`` ->
    ``sotpy.graph.pool.Pool.lock`` (an attribute of an instance's class); module data
    keeps the module it is read from.
    """
    import inspect

    found = _lookup(path)
    if found is None:
        return []
    obj, owner, name = found
    if inspect.ismodule(obj):
        return [obj.__name__]
    module = getattr(obj, "__module__", None)
    qualname = getattr(obj, "__qualname__", None)
    defined_here = not inspect.isclass(owner) or bool(qualname and qualname.endswith("." + name))
    if (inspect.isclass(obj) or inspect.isfunction(obj)) and module and qualname and defined_here:
        return [f"{module}.{qualname}"]
    if inspect.ismodule(owner):
        return [f"{owner.__name__}.{name}"]
    cls = owner if inspect.isclass(owner) else type(owner)
    mro = [base for base in cls.__mro__ if base is not object]
    defining = [base for base in mro if name in vars(base)]
    return [f"{base.__module__}.{base.__qualname__}.{name}" for base in defining + mro]


def _scopes(node) -> list[str]:
    """The scopes a name in a docstring is looked up in, innermost first, as Python
    would: the class, the module, the module's package (for ``.sibling`` references)."""
    module = node.get("py:module") or ""
    cls = node.get("py:class") or ""
    scopes = []
    if module and cls:
        scopes.append(f"{module}.{cls}")
    if module:
        scopes.append(module)
        if "." in module:
            scopes.append(module.rpartition(".")[0])
    return scopes


def _relative_names(app, doctree):
    """Resolve Python names in docstrings as Python would, when Sphinx would guess.

    A reference with a leading dot (``:mod:`.tasks```) and every name in a type hint are
    searched by Sphinx by suffix, which is ambiguous (``.tasks``: ``sotpy.tasks`` or
    ``sotpy.solvers.wbc.tasks``; ``list``: ``SOT.list``...). Rewrite them to the object
    the name denotes in the docstring's class, module or package; built-in names are
    searched exactly, so that they stay plain text.
    """
    from sphinx import addnodes

    for node in doctree.findall(addnodes.pending_xref):
        if node.get("refdomain") != "py" or not node.hasattr("refspecific"):
            continue
        target = node.get("reftarget", "")
        if target in _BUILTINS:
            del node["refspecific"]
            continue
        for scope in _scopes(node):
            names = _canonical(f"{scope}.{target}")
            if names:
                node["reftarget"] = names[0]
                del node["refspecific"]
                break


def _imported_names(app, env, node, contnode):
    """Resolve a name Sphinx did not find to where the docstring's module imports it from.

    Docstrings say :class:`SignalType` or :meth:`Pool.getSignal` for names their module
    imports and ``sotpy.graph.Tracer`` for re-exports; autodoc documents each object once,
    where it is defined. A name that resolves to no documented object stays broken.
    """
    from sphinx.util.nodes import make_refnode

    if node.get("refdomain") != "py":
        return None
    objects = env.get_domain("py").objects
    target = node.get("reftarget", "")
    names = [n for scope in _scopes(node) for n in _canonical(f"{scope}.{target}")]
    names += _canonical(target)
    # Last, a name imported only for type checking (``Pool`` in signal.py): accept it if
    # exactly one documented object ends with it.
    suffixed = [n for n in objects if n.endswith("." + target)]
    if len(suffixed) == 1:
        names += suffixed
    for name in names:
        if name in objects:
            entry = objects[name]
            return make_refnode(
                app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, name
            )
    return None


def _sentence_attribute_docstrings():
    """Read a property's docstring as prose.

    napoleon reads the first line of an attribute's docstring as ``type: description``;
    sotpy's property and command docstrings are sentences ("The control type: velocity,
    acceleration or torque"), and their types come from the annotations.
    """
    from sphinx.ext.napoleon.docstring import GoogleDocstring

    def consume(self):
        lines = self._dedent(self._consume_to_end())
        return "", self.__class__(lines, self._config).lines()

    GoogleDocstring._consume_inline_attribute = consume


_sentence_attribute_docstrings()


def _command_usage(app, what, name, obj, options, lines):
    """Start a command's entry with its call signature (autodoc lists a ``@command``,
    a descriptor, as an attribute, without one)."""
    from sotpy.graph.command import Command

    if isinstance(obj, Command):
        lines[:0] = [f"Command ``{obj.usage()}``.", ""]


def setup(app):
    app.connect("autodoc-process-docstring", _command_usage)
    app.connect("doctree-read", _relative_names)
    app.connect("missing-reference", _imported_names)


html_theme = "alabaster"
html_title = f"sotpy {release}"
