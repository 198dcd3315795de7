"""`cap bench controllers`: generated controllers (cart-pole balance, impedance under a push, tracking a moving
goal) through the real graph."""
