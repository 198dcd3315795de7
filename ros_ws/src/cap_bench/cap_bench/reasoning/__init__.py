"""Spatial-geometric reasoning questions, answered with code, with plain language and with chain of thought."""
