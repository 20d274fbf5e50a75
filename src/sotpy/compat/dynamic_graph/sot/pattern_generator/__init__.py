"""sot-pattern-generator's module: the walking ``PatternGenerator`` and the ``Selector``,
sotpy's own (:class:`sotpy.walking.PatternGenerator`, :class:`sotpy.operators.Selector`:
its Python meta constructor ``Selector(name, [type, out, in0, in1, ...], ...)`` too)."""

from sotpy.operators import Selector
from sotpy.walking import PatternGenerator

__all__ = ["PatternGenerator", "Selector"]
