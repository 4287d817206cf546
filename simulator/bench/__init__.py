"""The simulator's benchmarks (``heft bench accuracy|generated|zenoh|noise|sweep|changes``)."""
