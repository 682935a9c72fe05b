"""Benchmarks (``cloth-sim bench …``): they print figures; nothing here is asserted in tests."""
