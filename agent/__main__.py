"""``python -m agent``: the ``heft`` command (see :mod:`agent.platform.heft`)."""

from agent.platform.heft import main

raise SystemExit(main())
