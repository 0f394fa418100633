#!/usr/bin/env python3
"""Is the candidate build slower than the base build? Interleaved A/B timing on a noisy machine.

usage: bench/ab_compare.py BASE_BUILD CANDIDATE_BUILD [--rounds 10] [--repetitions 5] [--threshold 0.10]
                           [--out DIR] [--filter-table1 REGEX] [--filter-search REGEX]

BASE_BUILD and CANDIDATE_BUILD are build folders holding bench/bench_table1 and bench/bench_search
(the same folder twice measures the method's own noise). Two runs made minutes apart on a shared
2-core VM differ by 20-30 % as a whole (docs/benchmarks.md), so comparing two separate runs cannot
resolve a 10 % change. Here the two builds take turns: each round runs every row on each build, back
to back, in alternating order (ABBA...), and each round gives one paired ratio candidate/base per
row. Load that drifts over minutes affects both halves of a pair alike and cancels in the ratio;
within a half-round a row is repeated and its fastest repetition kept (interference only ever adds
time, so the minimum is the least disturbed estimate).

A row is SLOWER when the median paired ratio exceeds 1 + 3/4 threshold AND at least 80 % of the
rounds agree (ratio > 1): a 10 % regression (median ~1.10) passes both, while the method's own
noise (A against A: medians within 3 %, ratios on both sides of 1) passes neither, nor does the few
percent a relinked binary's code alignment can move an untouched row. FASTER likewise.
Exit status 1 when any row is SLOWER. Writes ab.md and ab.json to --out (default out/bench-ab).
"""
import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys

# The quick set: Table I's reduced rows and the exact search, plus two rows a change to minemap's
# search cannot move (nanoflann, the slice filter) as controls. All-points registrations take
# 0.5 s a repetition and measure the same search as the rows here.
QUICK_TABLE1 = "Table1_Pair/(mine|lidar)/cpu/reduced_apx/|Table1_Pair/mine/cpu/reduced_kd_accelerated/"
QUICK_SEARCH = ("NearestNeighbour_minemap/(mine|lidar)/cpu_exact/|NearestNeighbour_nanoflann_tbb/mine/"
                "|SliceFilter/cpu")


def run_once(build, program, pattern, repetitions):
    """Every matching row, repeated; returns {row: fastest repetition in seconds}."""
    binary = pathlib.Path(build) / "bench" / program
    command = [str(binary), f"--benchmark_filter={pattern}", f"--benchmark_repetitions={repetitions}",
               "--benchmark_format=json", "--benchmark_min_time=0.05"]
    env = dict(os.environ, MINEMAP_BENCH_SLAM_SCANS=os.environ.get("MINEMAP_BENCH_SLAM_SCANS", "6"))
    out = subprocess.run(command, check=True, capture_output=True, text=True, env=env).stdout
    times = {}
    for b in json.loads(out)["benchmarks"]:
        if b.get("error_occurred") or b.get("run_type") == "aggregate":
            continue
        scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3, "s": 1.0}[b["time_unit"]]
        seconds = b["real_time"] * scale
        times[b["run_name"]] = min(seconds, times.get(b["run_name"], seconds))
    return times


def verdict(ratios, threshold):
    middle = statistics.median(ratios)
    above = sum(r > 1.0 for r in ratios) / len(ratios)
    if middle > 1.0 + 0.75 * threshold and above >= 0.8:
        return "SLOWER"
    if middle < 1.0 - 0.75 * threshold and above <= 0.2:
        return "faster"
    return "same"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base")
    parser.add_argument("candidate")
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--repetitions", type=int, default=5)
    parser.add_argument("--threshold", type=float, default=0.10)
    parser.add_argument("--out", default="out/bench-ab")
    parser.add_argument("--filter-table1", default=QUICK_TABLE1)
    parser.add_argument("--filter-search", default=QUICK_SEARCH)
    args = parser.parse_args()
    programs = [("bench_table1", args.filter_table1), ("bench_search", args.filter_search)]
    samples = {}  # row -> list of (base seconds, candidate seconds), one per round
    for round_index in range(args.rounds):
        order = [("base", args.base), ("candidate", args.candidate)]
        if round_index % 2:
            order.reverse()
        for program, pattern in programs:
            timed = {label: run_once(build, program, pattern, args.repetitions) for label, build in order}
            for row in timed["base"].keys() & timed["candidate"].keys():
                samples.setdefault(row, []).append((timed["base"][row], timed["candidate"][row]))
        print(f"round {round_index + 1}/{args.rounds} done", file=sys.stderr)

    rows = []
    for row in sorted(samples):
        ratios = [c / b for b, c in samples[row]]
        rows.append({
            "row": row,
            "base_median_s": statistics.median(b for b, _ in samples[row]),
            "candidate_median_s": statistics.median(c for _, c in samples[row]),
            "median_ratio": statistics.median(ratios),
            "min_ratio": min(ratios),
            "max_ratio": max(ratios),
            "rounds_slower": sum(r > 1.0 for r in ratios),
            "rounds": len(ratios),
            "verdict": verdict(ratios, args.threshold),
        })
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = [f"A/B: base `{args.base}`, candidate `{args.candidate}`, {args.rounds} interleaved rounds, "
             f"fastest of {args.repetitions} repetitions per half-round, threshold {args.threshold:.0%}", "",
             "| row | base (median) | candidate (median) | candidate/base: median | range | rounds slower | verdict |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['row']} | {r['base_median_s'] * 1e3:.2f} ms | {r['candidate_median_s'] * 1e3:.2f} ms | "
                     f"{r['median_ratio']:.3f} | {r['min_ratio']:.3f}-{r['max_ratio']:.3f} | "
                     f"{r['rounds_slower']}/{r['rounds']} | {r['verdict']} |")
    table = "\n".join(lines) + "\n"
    for name, text in (("ab.md", table), ("ab.json", json.dumps(rows, indent=1))):
        temporary = out / (name + ".tmp")
        temporary.write_text(text)
        temporary.replace(out / name)
    print(table)
    return 1 if any(r["verdict"] == "SLOWER" for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
