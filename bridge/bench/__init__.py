"""The CAN bridge's benchmarks (``heft bench can``)."""
