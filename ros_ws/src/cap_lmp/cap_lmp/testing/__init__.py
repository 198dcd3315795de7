"""Real components for tests of cap_lmp and the packages above it (no mocks here)."""
