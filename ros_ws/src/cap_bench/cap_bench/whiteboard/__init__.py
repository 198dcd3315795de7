"""`cap bench whiteboard`: drawing and erasing on the simulated whiteboard, judged on the ink."""
