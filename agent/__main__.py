"""``python -m agent``: the ``heft`` command (see :mod:`agent.dispatch`)."""

from agent.dispatch import main

raise SystemExit(main())
