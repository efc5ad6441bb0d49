"""Measured speed and accuracy. Each `bench_*.py` module defines `run(shared) -> dict`."""
