"""The table-top development set: everyday commands judged on the simulator's final state (`cap bench devset`)."""
