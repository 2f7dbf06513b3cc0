"""Benchmarks: the paper's Section 4 reproduced on the simulated fleet, plus the scale goals.

`python -m bench.run --quick|--full` runs everything and writes bench/results/.
"""
