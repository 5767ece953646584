"""Test-wide settings.

Hypothesis draws its examples derandomized by default (the "gate" profile), so `make test` and CI draw
the same examples on every run: a red run is a real failure that reproduces, not a lucky draw. To hunt
for new failures with fresh random examples, run `pytest --hypothesis-profile=explore` and turn what it
finds into a fixed example or a fix.
"""
from hypothesis import settings

settings.register_profile("gate", derandomize=True, database=None, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile("gate")
