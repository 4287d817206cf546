"""``python -m heft``: the ``heft`` command line (see :mod:`heft.cli`)."""

from heft.cli import main

raise SystemExit(main())
