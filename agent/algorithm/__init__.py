"""The robot's algorithm: the paper's seven steps, the phases and their force laws, as
plain I/O-free classes (one robot's :class:`~agent.algorithm.agent.Agent`)."""
