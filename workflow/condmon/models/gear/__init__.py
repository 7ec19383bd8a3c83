"""The geared drivetrain (`system: gear`; the `cfrp` system builds it from its own parameters)."""
