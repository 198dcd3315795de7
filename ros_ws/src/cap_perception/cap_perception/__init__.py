"""Object perception for cap-ros: simulator ground truth, RGB-D colour detector, YAML stub, perception node."""
