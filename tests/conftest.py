"""Test-wide settings: property-based tests draw the same examples on every run, so CI is
deterministic (a new random example must not turn an unchanged tree red)."""

from hypothesis import settings

settings.register_profile("deterministic", derandomize=True, database=None)
settings.load_profile("deterministic")
