"""Language model programs: prompts, hierarchical code generation, sandboxed execution, LLM clients, lmp_node."""
