"""The robust estimators: the paper's steps on noisy odometry, noisy force sensing and drives
with lag and gain errors. :mod:`~agent.algorithm.robust.pipeline` runs them,
:mod:`~agent.algorithm.robust.phases` holds their force laws, :mod:`~agent.algorithm.robust.
tuning` their gains, :mod:`~agent.algorithm.robust.uncertainty` what they publish; one module
per estimator."""
