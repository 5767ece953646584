"""Keeping the cyclic garbage collector off a large tree that has no cycles.

Parsing builds an AST of about a million small objects per 5 MB of source, and checking adds its
tables; none of them can form a reference cycle. With the collector running, every collection of
the young generation walks the half-built tree again. With it merely paused, the first allocation
after it is resumed pays for one walk of everything allocated meanwhile (about a quarter of the
parse time of a large file, measured), and the next older-generation collection for another.

`paused()` stops the collector while the block runs, and at its end moves everything it tracks to
the oldest generation without a walk (`gc.freeze()` then `gc.unfreeze()`: two list splices), so
the tree is looked at only by the full collections that CPython runs in proportion to the
long-lived heap. Nothing is exempted for good: garbage cycles the caller made before the call are
collected by the next full collection instead of the next young one. When something else has
frozen objects (`gc.get_freeze_count()`: a pre-fork server, say), the splice would unfreeze them, so
it is skipped. A caller that had the collector off keeps it off.
"""
from __future__ import annotations

import gc
from contextlib import contextmanager


@contextmanager
def paused():
    if not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        if gc.get_freeze_count() == 0:
            gc.freeze()
            gc.unfreeze()
        gc.enable()
