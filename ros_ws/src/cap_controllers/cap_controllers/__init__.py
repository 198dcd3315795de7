"""Facts of the reactive-controller domain, pure Python: the plants a generated controller drives (the cart-pole and
the UR5e under torque control), their state layouts, actuator and safety limits, and the control loop's rates."""
