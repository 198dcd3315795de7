"""Facts of the mobile kitchen domain: the room, its furniture, named locations and bins, the mobile base."""
