"""The paper's simulated table-top benchmark: episodes, instructions, success checks, oracle programs and the
runs through the graph (`cap bench tabletop`, bench.py)."""
