"""The simulator's benchmarks (``heft bench accuracy|zenoh|noise|changes``)."""
