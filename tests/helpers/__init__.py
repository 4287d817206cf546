"""What several test modules share, whatever their level (no test module imports another):
paths, the accuracy checks of a run against the ground truth, processes, fakes of a Zenoh
session's parts, TLS placeholders, bad input files, frames and messages to refuse, a noise
benchmark's results with known errors, and ``heft`` command lines as the docs and units write
them."""
