"""Multibody models and their physics: pure functions of parameters, returning signals."""
