"""The web console: a page on 127.0.0.1 that shows the graph and commands it (cap console, cap up --console)."""
