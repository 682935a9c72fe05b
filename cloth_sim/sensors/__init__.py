"""Sensors that look at the simulation: the depth camera (:mod:`.camera`)."""
