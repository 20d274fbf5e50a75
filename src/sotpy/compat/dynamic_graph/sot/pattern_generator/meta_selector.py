"""sot-pattern-generator's ``meta_selector``: sotpy's ``Selector`` takes the meta
constructor's lists itself."""

from sotpy.operators import Selector

__all__ = ["Selector"]
