"""Pick-and-place by the mobile manipulator: plan (where the base stands, the arm's stages), executor (navigation,
then the table top's plan runner) and node (the MobilePickPlace action)."""
