"""The errors of the compatibility layer."""

from __future__ import annotations

from ..errors import SotpyError

__all__ = ["UnsupportedFeature", "UnsupportedModule", "unsupported"]


class UnsupportedFeature(SotpyError, NotImplementedError):
    """A feature of the C++ Stack of Tasks that ``sotpy run`` does not provide.

    ``feature`` names it, ``equivalent`` says what to use in sotpy instead.
    """

    def __init__(self, feature: str, equivalent: str) -> None:
        super().__init__(
            f"{feature} is not supported by sotpy's SoT compatibility layer (sotpy run); "
            f"sotpy's equivalent: {equivalent}"
        )
        self.feature = feature
        self.equivalent = equivalent


class UnsupportedModule(SotpyError, ImportError):
    """A ``dynamic_graph`` module that ``sotpy run`` does not serve (an ``ImportError``,
    so that ``try: import ... except ImportError`` still works)."""

    def __init__(self, module: str, equivalent: str) -> None:
        super().__init__(
            f"module {module!r} is not served by sotpy's SoT compatibility layer (sotpy "
            f"run); sotpy's equivalent: {equivalent}",
            name=module,
        )
        self.feature = module
        self.equivalent = equivalent


def unsupported(feature: str, equivalent: str) -> UnsupportedFeature:
    """The error to raise for an unsupported SoT feature."""
    return UnsupportedFeature(feature, equivalent)
