"""Benchmarks: work-precision runs of our integrators and of peer simulators on the spec's scenes."""
