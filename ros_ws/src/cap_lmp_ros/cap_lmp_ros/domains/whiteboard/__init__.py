"""The whiteboard domain: drawing and erasing shapes on a whiteboard with the UR5e (the paper's second domain)."""
