"""The paper's simulated table-top benchmark: episodes, instructions, success checks and oracle programs."""
