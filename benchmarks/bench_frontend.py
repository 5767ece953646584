"""Front-end throughput: rgm's parse (+ check) beside a plain lark LALR parse of the same text.

Workloads:
  (a) a generated statement-heavy file of about 5 MB: params, points, lines, revolutions with @fit
      annotations and comments, small 4 x 4 nets, exports (targets: >= 1 MB/s parse + check);
  (b) one bicubic surface holding a 1000 x 1000 control net in the dense `net` form, about 27 MB
      (target: >= 30 MB/s parse + check).
For each: rgm's parse (lark's LALR table run once per statement shape and compiled, nets read by
numpy: rgm.compiler.lalr, rgm.compiler.netbody), rgm's parse + check
(`rgm.compiler.check`, skipped with a message if it is not importable), lark's own LALR parse of the
same grammar building its generic parse tree (the peer: what `Lark(parser="lalr")` costs without
any AST), and for (a) rgm's parse through lark's parse loop (`fast=False`).

The machine running this may be shared: besides wall-clock MB/s the script prints CPU-time MB/s
(time.process_time) and the load average, and a calibration loop's speed relative to a nominal
50 M simple iterations/s, so figures from a loaded machine can be read for what they are. Each
workload ends with a PASS/FAIL line for its target, judged on wall-clock time; every figure is of a
single cold run (one parse of text the process has not parsed before, as `rgmc check` does).

Run: python benchmarks/bench_frontend.py [--small]   (--small: 1 MB and 300 x 300, for a quick look)
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np
from lark import Lark

from rgm.compiler.parser import parse
from rgm.grammar import grammar_text

try:
    from rgm.compiler.check import check
except ImportError:     # the checker is another module; the benchmark still measures parsing
    check = None


def statement_heavy(target_bytes: int) -> str:
    """A valid, checkable program of about `target_bytes`, built from a repeating group of statements."""
    head = ["# generated for bench_frontend: a statement-heavy model", "units mm;", "tolerance 0.01;", "",
            "param r := 27.15mm;", "axis := line(pt(0, 0, 0), pt(0, 1, 0));"]
    group = """
# part {i}: a profile and its revolution
p{i} := pt({x}mm, {i}, -3.25);  # corner
q{i} := p{i} + vec(r, 2 * {y}, 0);
c{i} := polyline([p{i}, q{i}, q{i} + vec(0, 5mm, 0)]);
@classified(as: "cylinder", confidence: 0.93, runner_up: "other_revolution")
@fit(points: 18214, max: 0.081mm, rms: 0.021mm, p95: 0.05mm, tol: 0.1mm)
s{i} := revolve(translate(c{i}, vec(r + {x}mm, 0, 0)), axis, from: 0deg, to: 90deg * 2);
export s{i}, b{i};
b{i} := bsurface(degree_u: 3, degree_v: 3, knots_u: uniform(3, 4), knots_v: uniform(3, 4),
    net: net 4 x 4 [0 0 {i}, 1 0 0, 2 0 0, 3 0 0, 0 1 0, 1 1 1, 2 1 1, 3 1 0, 0 2 0, 1 2 1, 2 2 1, 3 2 0,
                    0 3 0, 1 3 0, 2 3 0, 3 3 0]);
"""
    parts, size, i = ["\n".join(head)], 0, 0
    while size < target_bytes:
        text = group.format(i=i, x=round(1.5 + i * 0.001, 3), y=i % 97)
        parts.append(text)
        size += len(text)
        i += 1
    return "".join(parts)


def big_net(n: int, rng) -> str:
    """One bicubic surface with an n x n control net written in the dense form (values like a fit's)."""
    u = np.linspace(0, 100, n)
    x, y = np.meshgrid(u, u, indexing="ij")
    z = 8 * np.exp(-((x - 50) ** 2 + (y - 50) ** 2) / 1800) + rng.normal(0, 0.01, x.shape)
    pts = np.stack([x, y, z], -1).round(4).reshape(n, n * 3)
    rows = [", ".join(" ".join(t) for t in zip(*[iter(map(repr, row.tolist()))] * 3)) for row in pts]
    body = ",\n    ".join(rows)
    return (f"# generated for bench_frontend: one surface, {n} x {n} control points\nunits mm;\n"
            f"surface := bsurface(degree_u: 3, degree_v: 3, knots_u: uniform(3, {n}), knots_v: uniform(3, {n}),\n"
            f"  net: net {n} x {n} [\n    {body}\n  ]);\nexport surface;\n")


def timed(fn):
    """(wall seconds, cpu seconds, result) of one call."""
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - w, time.process_time() - c, out


def calibration() -> float:
    """Simple loop iterations per second / 50e6: about 1 on an idle modern core."""
    n = 2_000_000
    w = time.perf_counter()
    for _ in range(n):
        pass
    return n / (time.perf_counter() - w) / 50e6


def report(label: str, text: str, plain: Lark, slow_too: bool, target: float) -> None:
    mb = len(text.encode()) / 1e6
    print(f"\n{label}: {mb:.2f} MB")
    rows = []
    wall, cpu, (program, diags) = timed(lambda: parse(text, "bench.rgm"))
    errors = [d for d in diags if d.is_error]
    rows.append(("rgm parse", wall, cpu))
    if check is not None:
        w2, c2, result = timed(lambda: check(program))
        errors += [d for d in result.diagnostics if d.is_error]
        rows.append(("rgm parse + check", wall + w2, cpu + c2))
    else:
        print("  (rgm.compiler.check not importable: parse only)")
    judged, total_wall, total_cpu = rows[-1]
    if slow_too:
        w3, c3, _ = timed(lambda: parse(text, "bench.rgm", fast=False))
        rows.append(("rgm parse via lark's loop", w3, c3))
    w4, c4, _ = timed(lambda: plain.parse(text))
    rows.append(("lark LALR parse tree (peer)", w4, c4))
    for name, w, c in rows:
        print(f"  {name:30s} {w:7.2f} s  {mb / w:7.2f} MB/s wall   {mb / c:7.2f} MB/s cpu")
    print(f"  statements: {len(program.statements)}, errors: {len(errors)}"
          + (f" (first: {errors[0].message})" if errors else ""))
    peer = rows[-1][1]
    print(f"  {judged} is {peer / total_wall:.1f}x the speed of lark's parse tree alone (wall)")
    verdict = "PASS" if mb / total_wall >= target and not errors else "FAIL"
    print(f"  target: {judged} >= {target:g} MB/s: {verdict} ({mb / total_wall:.2f} MB/s wall, "
          f"{mb / total_cpu:.2f} MB/s cpu)")


def main(argv: list[str]) -> int:
    small = "--small" in argv
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cpus; "
          f"calibration {calibration():.2f} x nominal Python speed")
    plain = Lark(grammar_text(), parser="lalr", lexer="contextual")
    parse("warm := 1;", "warm.rgm")
    report("(a) statement-heavy file", statement_heavy(1_000_000 if small else 5_000_000), plain, True, 1.0)
    n = 300 if small else 1000
    report(f"(b) {n} x {n} control net", big_net(n, np.random.default_rng(0)), plain, False, 30.0)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
