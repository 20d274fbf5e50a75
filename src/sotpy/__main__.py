"""``python -m sotpy``: the ``sotpy`` command line (see :mod:`sotpy.cli`)."""

from .cli import main

raise SystemExit(main())
