#!/usr/bin/env python3
"""Compares two benchmark runs (Google Benchmark JSON) row by row: is the new run slower?

usage: bench/compare.py BASE.json NEW.json [--threshold 0.10]

For each benchmark in both files, prints the median real time of its repetitions in each run, the
ratio new/base and each run's relative spread ((max - min) / median). A row is flagged SLOWER when
its median grew by more than the threshold (default 10 %) AND the two runs' ranges do not overlap,
so noise the repetitions themselves show is not called a regression. Exit status 1 when any row is
flagged, so a CI timing study can gate on it. bench/run_benchmarks.sh --quick writes such JSON.
"""
import argparse
import collections
import json
import statistics
import sys


def load(path):
    runs = collections.defaultdict(list)
    for b in json.load(open(path))["benchmarks"]:
        if b.get("run_type") == "aggregate" or b.get("error_occurred"):
            continue
        scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}[b["time_unit"]]
        runs[b["run_name"]].append(b["real_time"] * scale)
    return runs


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base")
    parser.add_argument("new")
    parser.add_argument("--threshold", type=float, default=0.10, help="relative slowdown that counts (0.10 = 10 %%)")
    args = parser.parse_args()
    base, new = load(args.base), load(args.new)
    flagged = 0
    print(f"{'benchmark':70s} {'base':>10s} {'new':>10s} {'new/base':>9s} {'spread b/n':>12s}")
    for name in sorted(set(base) & set(new)):
        b, n = base[name], new[name]
        mb, mn = statistics.median(b), statistics.median(n)
        spread = f"{(max(b) - min(b)) / mb:5.1%}/{(max(n) - min(n)) / mn:5.1%}"
        slower = mn > mb * (1 + args.threshold) and min(n) > max(b)
        flagged += slower
        print(f"{name:70s} {mb * 1e3:8.2f}ms {mn * 1e3:8.2f}ms {mn / mb:9.3f} {spread:>12s}{'  SLOWER' if slower else ''}")
    print(f"{flagged} of {len(set(base) & set(new))} rows slower by more than {args.threshold:.0%}")
    return 1 if flagged else 0


if __name__ == "__main__":
    sys.exit(main())
