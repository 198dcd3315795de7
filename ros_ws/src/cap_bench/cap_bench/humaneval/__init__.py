"""HumanEval (Chen et al. 2021) run in the project's sandbox: the problems and what the harness allows."""
