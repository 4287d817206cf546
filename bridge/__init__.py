"""The CAN side of Heft: AGV frames, the CAN bridge, and virtual CAN buses for tests."""
