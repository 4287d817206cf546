"""The team's dashboard: live and replayed views of the estimates converging, and recordings.

A browser page (``heft dashboard``) shows every robot's m̂ and Ĵ against the truth, the edges'
``‖z_ij‖`` and each robot's distance to the COM (each with the 95 % band its robot publishes,
if it does), ``ω``, the phase timeline, the communication graph's health and a top view of the
load; ``heft record`` writes a team's traffic to MCAP, which the dashboard replays (``heft
dashboard --replay FILE``).

Modules, one job each: :mod:`dashboard.channels` (Zenoh keys and protocol messages as the
recordings' JSON channels), :mod:`dashboard.quantities` (the estimated scalars the page shows,
declared once), :mod:`dashboard.state` (pure aggregation of the messages into what the page
shows), :mod:`dashboard.feed` (the live Zenoh subscription), :mod:`dashboard.recorder` and
:mod:`dashboard.replay` (MCAP), :mod:`dashboard.hub` (the state shared by the sources and the
web app), :mod:`dashboard.app` (the FastAPI app), :mod:`dashboard.server` (uvicorn in a
thread), :mod:`dashboard.display` (the page and a recorder as parts of a process),
:mod:`dashboard.companion` (both beside a run of ``heft run``/``heft demo``),
:mod:`dashboard.foxglove_live` (the team live to Foxglove through the Foxglove SDK's WebSocket
server), :mod:`dashboard.relay` (that server on the app's own port, behind its token),
:mod:`dashboard.log_entries` (the agents' log lines as Foxglove log messages),
:mod:`dashboard.cli` (``heft dashboard``, ``heft record``); its benchmark, ``heft bench
dashboard``, is :mod:`dashboard.bench`. The load's outline and the graph are the plant's
(:class:`~agent.platform.protocol.LoadGeometry`), heard as the rest of the team's messages.
"""
