"""``python -m agent``: the ``heft`` command (see :mod:`agent.platform.dispatch`)."""

from agent.platform.dispatch import main

raise SystemExit(main())
