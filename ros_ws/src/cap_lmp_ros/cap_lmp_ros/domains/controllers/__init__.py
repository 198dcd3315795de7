"""The reactive-controller domain: generated controller functions run at a fixed rate by controller_node."""
