#!/usr/bin/env python3
"""Counts the instructions of Table I's pair rows in two builds (callgrind): a timing study that noise
cannot move.

usage: bench/count_instructions.py BASE_BUILD [CANDIDATE_BUILD] [--threshold 0.03] [--rows REGEX]
                                   [--out DIR]

Each row runs once per build under `valgrind --tool=callgrind`, on one TBB thread
(MINEMAP_BENCH_THREADS=1: worker threads spin while they wait, which would add a varying count),
collecting only inside the benchmark function (the shared inputs are built before it). The count is
the same to the instruction from run to run on the same binary, whatever else the machine does (two
runs of the mine reduced row: 3,072,831,621 both times), so a change in it is the code's. It counts
work, not time: a change that only moves data around (cache misses) does not show; bench/ab_compare.py
measures time. A row is SLOWER when the candidate executes more than (1 + threshold) times the
base's instructions (default 3 %: no noise needs a margin, only changes too small to matter);
exit status 1 then. With one build, it prints that build's counts.
Writes instructions.md and instructions.json to --out (default out/bench-instructions).
About 10 s per row and build on 2 cores (valgrind runs ~50x slower than native).
"""
import argparse
import json
import os
import pathlib
import re
import subprocess
import sys
import tempfile

ROWS = ("Table1_Pair/mine/cpu/(reduced_apx|reduced_kd_accelerated)/"
        "|Table1_Pair/lidar/cpu/(reduced_apx|reduced_kd_accelerated)/")


def list_rows(build, pattern):
    binary = pathlib.Path(build) / "bench" / "bench_table1"
    listed = subprocess.run([str(binary), f"--benchmark_filter={pattern}", "--benchmark_list_tests"],
                            check=True, capture_output=True, text=True).stdout
    return [line.strip() for line in listed.splitlines() if line.strip()]


def count(build, row):
    """Instructions executed inside the benchmark function for `row` (one run, 1 thread)."""
    binary = pathlib.Path(build) / "bench" / "bench_table1"
    with tempfile.TemporaryDirectory() as scratch:
        out_file = pathlib.Path(scratch) / "callgrind.out"
        command = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}",
                   "--toggle-collect=*BM_Table1_Pair*", str(binary),
                   f"--benchmark_filter=^{re.escape(row)}$"]
        env = dict(os.environ, MINEMAP_BENCH_THREADS="1")
        subprocess.run(command, check=True, capture_output=True, text=True, env=env)
        for line in out_file.read_text().splitlines():
            if line.startswith("totals:"):
                return int(line.split()[1])
    raise RuntimeError(f"no instruction total for {row} in {build}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base")
    parser.add_argument("candidate", nargs="?")
    parser.add_argument("--threshold", type=float, default=0.03)
    parser.add_argument("--rows", default=ROWS)
    parser.add_argument("--out", default="out/bench-instructions")
    args = parser.parse_args()
    builds = [args.base] + ([args.candidate] if args.candidate else [])
    results = []
    for row in list_rows(args.base, args.rows):
        counts = [count(build, row) for build in builds]
        entry = {"row": row, "base_instructions": counts[0]}
        if args.candidate:
            ratio = counts[1] / counts[0]
            entry.update(candidate_instructions=counts[1], ratio=ratio,
                         verdict="SLOWER" if ratio > 1 + args.threshold else
                                 "fewer" if ratio < 1 - args.threshold else
                                 "same" if counts[1] == counts[0] else "changed")
        results.append(entry)
        print(f"{row}: {counts}", file=sys.stderr)
    if args.candidate:
        lines = [f"Instructions (callgrind, 1 thread): base `{args.base}`, candidate `{args.candidate}`, "
                 f"threshold {args.threshold:.0%}", "",
                 "| row | base | candidate | candidate/base | verdict |", "|---|---|---|---|---|"]
        lines += [f"| {r['row']} | {r['base_instructions']:,} | {r['candidate_instructions']:,} | "
                  f"{r['ratio']:.4f} | {r['verdict']} |" for r in results]
    else:
        lines = [f"Instructions (callgrind, 1 thread): `{args.base}`", "", "| row | instructions |", "|---|---|"]
        lines += [f"| {r['row']} | {r['base_instructions']:,} |" for r in results]
    table = "\n".join(lines) + "\n"
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, text in (("instructions.md", table), ("instructions.json", json.dumps(results, indent=1))):
        temporary = out / (name + ".tmp")
        temporary.write_text(text)
        temporary.replace(out / name)
    print(table)
    return 1 if any(r.get("verdict") == "SLOWER" for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
