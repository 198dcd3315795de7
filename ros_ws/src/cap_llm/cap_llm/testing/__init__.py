"""Real components for tests and demos of cap_llm and the packages above it (no mocks here)."""
