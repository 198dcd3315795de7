"""The Code as Policies benchmarks, one folder a benchmark (its bench.py is `cap bench <folder>`); the modules here
are what several of them share."""
