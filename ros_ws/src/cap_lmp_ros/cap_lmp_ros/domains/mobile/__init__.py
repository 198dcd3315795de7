"""The mobile kitchen domain: a mobile manipulator driven around a kitchen-office from language."""
