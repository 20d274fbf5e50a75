"""``python -m sotpy.compat SCRIPT.py [ARG ...]``: run a SoT script (see
:mod:`sotpy.compat`)."""

from . import main

raise SystemExit(main())
