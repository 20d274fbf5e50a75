"""Robot descriptions shipped with sotpy: one ``<name>.toml`` per robot, and the URDF
files they refer to (``nao.urdf``). Loaded by :mod:`sotpy.dynamics.robot`; the format is
documented in ``docs/robots.md``."""
