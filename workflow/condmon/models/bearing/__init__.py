"""The rolling-bearing rig (`system: bearing`)."""
