"""The mobile kitchen benchmark (`cap bench mobile`)."""
