"""Commands: the asynchronous interface of an entity.

A command is a method with typed arguments, a doc string and a return value. Its
arguments are checked and converted when it is called, from the method's annotations:

=====================  ====================================================
annotation             accepted, and stored as
=====================  ====================================================
``float``              int or float, not bool, not NaN -> ``float``
``int``                int (not bool) -> ``int``
``bool``               bool -> ``bool``
``str``                str
``numpy.ndarray``      anything ``numpy.array(x, float)`` takes, no NaN
a ``SignalType``       what the signal type converts (``VECTOR``, ...)
a class                an instance of it (an entity, a signal, ``SE3``)
``X | None``           ``None`` or what ``X`` accepts
none / ``Any``         anything
=====================  ====================================================

A wrong call raises :class:`~sotpy.errors.CommandError` naming the entity, the command,
the argument and what was expected; the command body does not run.
"""

from __future__ import annotations

import inspect
import math
import types
import typing
from collections.abc import Callable
from typing import Any

from ..errors import CommandError
from .types import SignalType

__all__ = ["BoundCommand", "Command", "command"]


class Command:
    """A typed entity command (made with the :func:`command` decorator)."""

    def __init__(self, fn: Callable[..., Any], name: str | None = None) -> None:
        self.fn = fn
        self._explicit_name = name is not None
        self.name = name or fn.__name__
        self.__doc__ = inspect.cleandoc(fn.__doc__ or "")
        self.signature = inspect.signature(fn)
        self._converters: dict[str, Callable[[Any], Any]] | None = None
        self._fast: tuple[int, int, list[tuple[str, Any]]] | None = None

    def __set_name__(self, owner: type, name: str) -> None:
        if not self._explicit_name:
            self.name = name

    def __get__(self, obj: Any, objtype: type | None = None) -> Any:
        if obj is None:
            return self
        return BoundCommand(self, obj)

    @property
    def summary(self) -> str:
        """The first paragraph of the doc string, on one line."""
        return " ".join(self.__doc__.split("\n\n", 1)[0].split()) if self.__doc__ else ""

    def usage(self) -> str:
        """``name(arg: type, ...) -> type``, without ``self``."""
        try:  # evaluate string annotations (``from __future__ import annotations``)
            sig = inspect.signature(self.fn, eval_str=True)
        except Exception:
            sig = self.signature
        params = list(sig.parameters.values())[1:]
        text = str(sig.replace(parameters=params))
        return f"{self.name}{text.replace('numpy.ndarray', 'ndarray')}"

    def call(self, entity: Any, args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
        """Check and convert the arguments, then run the command."""
        fast = self._fast
        if fast is None:
            fast = self._fast = self._make_fast_path()
        if not kwargs and fast[0] <= len(args) <= fast[1]:
            # positional call of a plain signature: no binding needed
            positional = fast[2]
            converted = list(args)
            for i, (name, convert) in enumerate(positional[: len(args)]):
                if convert is not None:
                    converted[i] = self._convert(entity, name, convert, args[i])
            return self.fn(entity, *converted)
        try:
            bound = self.signature.bind(entity, *args, **kwargs)
        except TypeError as exc:
            raise CommandError(
                f"{_who(entity)}.{self.name}: {exc}; usage: {self.usage()}"
            ) from None
        arguments = bound.arguments
        for name, convert in self._converters_map().items():
            if name in arguments:
                arguments[name] = self._convert(entity, name, convert, arguments[name])
        return self.fn(*bound.args, **bound.kwargs)

    def _convert(self, entity: Any, name: str, convert: Callable[[Any], Any], value: Any) -> Any:
        try:
            return convert(value)
        except (TypeError, ValueError) as exc:
            raise CommandError(
                f"{_who(entity)}.{self.name}: argument {name!r}: {exc}; usage: {self.usage()}"
            ) from None

    def _converters_map(self) -> dict[str, Callable[[Any], Any]]:
        if self._converters is None:
            self._converters = self._make_converters()
        return self._converters

    def _make_fast_path(self) -> tuple[int, int, list[tuple[str, Any]]]:
        """(fewest, most positional arguments, [(name, converter)]) for signatures made
        only of positional-or-keyword parameters; (1, 0, []) disables the fast path."""
        params = list(self.signature.parameters.values())[1:]
        if any(p.kind is not p.POSITIONAL_OR_KEYWORD for p in params):
            return (1, 0, [])
        converters = self._converters_map()
        required = sum(1 for p in params if p.default is p.empty)
        return (required, len(params), [(p.name, converters.get(p.name)) for p in params])

    def _make_converters(self) -> dict[str, Callable[[Any], Any]]:
        try:
            hints = typing.get_type_hints(self.fn, include_extras=True)
        except Exception:  # one unresolvable annotation: resolve the others one by one
            hints = {}
            scope = getattr(self.fn, "__globals__", {})
            for name, ann in getattr(self.fn, "__annotations__", {}).items():
                try:
                    hints[name] = eval(ann, scope) if isinstance(ann, str) else ann
                except Exception:
                    continue
        converters = {}
        for i, (name, param) in enumerate(self.signature.parameters.items()):
            if i == 0 or name not in hints:
                continue
            if param.kind in (param.VAR_POSITIONAL, param.VAR_KEYWORD):
                continue
            conv = _converter(hints[name])
            if conv is not None:
                converters[name] = conv
        return converters


class BoundCommand:
    """A command bound to an entity: call it, read its ``__doc__``."""

    __slots__ = ("command", "entity")

    def __init__(self, command: Command, entity: Any) -> None:
        self.command = command
        self.entity = entity

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.command.call(self.entity, args, kwargs)

    @property
    def __doc__(self) -> str:  # type: ignore[override]
        return self.command.__doc__

    @property
    def __name__(self) -> str:
        return self.command.name

    @property
    def __signature__(self) -> inspect.Signature:
        params = list(self.command.signature.parameters.values())[1:]
        return self.command.signature.replace(parameters=params)

    def __repr__(self) -> str:
        return f"<command {_who(self.entity)}.{self.command.usage()}>"


def command(fn: Callable[..., Any] | None = None, *, name: str | None = None) -> Any:
    """Declare an entity method as a typed command (``@command`` or
    ``@command(name="...")``)."""
    if fn is None:
        return lambda f: Command(f, name)
    return Command(fn, name)


def _who(entity: Any) -> str:
    cls = getattr(entity, "className", type(entity).__name__)
    return f"{cls}({getattr(entity, 'name', '?')})"


def _float(v: Any) -> float:
    import numpy as np

    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise TypeError(f"expected a real number, got {type(v).__name__} {v!r}")
    x = float(v)
    if math.isnan(x):
        raise ValueError("expected a real number, got NaN")
    return x


def _int(v: Any) -> int:
    import numpy as np

    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise TypeError(f"expected an integer, got {type(v).__name__} {v!r}")
    return int(v)


def _bool(v: Any) -> bool:
    import numpy as np

    if not isinstance(v, (bool, np.bool_)):
        raise TypeError(f"expected a bool, got {type(v).__name__} {v!r}")
    return bool(v)


def _str(v: Any) -> str:
    if not isinstance(v, str):
        raise TypeError(f"expected a string, got {type(v).__name__} {v!r}")
    return v


def _ndarray(v: Any) -> Any:
    import numpy as np

    if isinstance(v, (str, bytes)):
        raise TypeError(f"expected an array of real numbers, got {v!r}")
    try:
        a = np.array(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"expected an array of real numbers, got {v!r}") from None
    if np.isnan(a).any():
        raise ValueError(f"expected an array without NaN, got {v!r}")
    return a


def _converter(hint: Any) -> Callable[[Any], Any] | None:
    """The checker for one annotation, or None for no check."""
    import numpy as np

    if hint is Any or hint is inspect.Parameter.empty:
        return None
    origin = typing.get_origin(hint)
    if origin is typing.Annotated:
        for meta in typing.get_args(hint)[1:]:
            if isinstance(meta, SignalType):
                return meta.convert
        return _converter(typing.get_args(hint)[0])
    if origin in (typing.Union, types.UnionType):
        members = typing.get_args(hint)
        optional = type(None) in members
        rest = [m for m in members if m is not type(None)]
        convs = [_converter(m) for m in rest]
        if any(c is None for c in convs):
            return None

        def union(v: Any) -> Any:
            if v is None and optional:
                return None
            reasons = []
            for c in convs:
                try:
                    return c(v)  # type: ignore[misc]
                except (TypeError, ValueError) as exc:
                    reasons.append(str(exc))
            raise TypeError(" or ".join(reasons) + (" (or None)" if optional else ""))

        return union
    if isinstance(hint, SignalType):
        return hint.convert
    simple = {float: _float, int: _int, bool: _bool, str: _str, np.ndarray: _ndarray}
    if hint in simple:
        return simple[hint]
    if origin is not None:  # list[float], tuple[...]: checked by the command itself
        return None
    if isinstance(hint, type):

        def instance(v: Any) -> Any:
            if not isinstance(v, hint):
                raise TypeError(f"expected {hint.__name__}, got {type(v).__name__} {v!r}")
            return v

        return instance
    return None
