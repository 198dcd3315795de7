"""Robot code generation: 37 functions to write from their signature alone, judged on seeded test inputs."""
