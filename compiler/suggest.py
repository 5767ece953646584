"""Name suggestions by edit distance ("did you mean `profile`?"), after Nickel's core/src/error/suggest.rs.

A candidate is offered when its optimal-string-alignment distance (Levenshtein plus adjacent
transpositions) to the misspelt name is at most a third of the longer name (at least 1), or when the
two differ only in letter case.
"""
from __future__ import annotations

from collections.abc import Iterable


def edit_distance(a: str, b: str) -> int:
    """Optimal string alignment distance: insertions, deletions, substitutions, adjacent swaps cost 1."""
    if a == b:
        return 0
    prev2: list[int] | None = None
    prev = list(range(len(b) + 1))
    for i, ca in enumerate(a, 1):
        cur = [i] + [0] * len(b)
        for j, cb in enumerate(b, 1):
            cost = 0 if ca == cb else 1
            cur[j] = min(prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + cost)
            if prev2 is not None and i > 1 and j > 1 and ca == b[j - 2] and a[i - 2] == cb:
                cur[j] = min(cur[j], prev2[j - 2] + 1)
        prev2, prev = prev, cur
    return prev[-1]


def suggest(name: str, candidates: Iterable[str], limit: int = 1) -> list[str]:
    """The closest candidates to `name` (best first, ties alphabetical), or [] when none is close."""
    scored = []
    for cand in set(candidates):
        if cand == name:
            continue
        if cand.lower() == name.lower():
            scored.append((0, cand))
            continue
        dist = edit_distance(name, cand)
        if dist <= max(1, max(len(name), len(cand)) // 3):
            scored.append((dist, cand))
    scored.sort()
    return [cand for _dist, cand in scored[:limit]]


def did_you_mean(name: str, candidates: Iterable[str]) -> str | None:
    """A hint line "did you mean `x`?" or None."""
    best = suggest(name, candidates)
    return f"did you mean `{best[0]}`?" if best else None
