"""The paper's estimators (Franchi, Petitti, Rizzo, CDC 2014, Sec. IV-V and the Appendix):
exact without noise. :mod:`~agent.algorithm.paper.pipeline` runs them,
:mod:`~agent.algorithm.paper.phases` holds their force laws, :mod:`~agent.algorithm.paper.tuning`
their gains; one module per estimator."""
