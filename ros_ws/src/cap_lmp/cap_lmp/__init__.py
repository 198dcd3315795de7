"""Language model programs (pure Python): the LMP engine, hierarchical function generation, LLM clients,
cassettes and the sandbox."""
