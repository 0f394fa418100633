#!/usr/bin/env python3
"""Throughput of `minemap batch` against a plain loop, side by side in one run.

usage: bench/batch_throughput.py [--surveys K] [--scans N] [--repeat R] [--quick] [--out FILE]

Maps K simulated surveys (seeds 1..K, N scans each) with the same mapper command, each mode R times
(interleaved; the fastest run counts, since a shared machine only ever adds time):
  sequential   a loop over `minemap map SURVEY --threads 2`, one survey after the other
  batch_1x2    `minemap batch` as a user runs it: it starts a LocalCluster of 1 worker and runs
               each survey with --threads 2. Same parallelism as the loop: the engine's whole cost
  batch_1x2_warm  the same against a LocalCluster started beforehand: the cost per survey alone,
               as on a cluster that outlives the batch
  batch_2x1    `minemap batch` on 2 workers x 1 thread: two surveys at a time
The mapper is `python -m minemap` (the installed package), or MINEMAP_BATCH_COMMAND
(whitespace-split, e.g. build/minemap). Writes JSON to --out (default
out/bench-batch/batch_throughput.json).

The engine's overhead is also measured within each run, where other load on the machine slows the
mappers and the total alike: the wall time less the sum of the mappers' own times (batch.json's
"seconds"; the loop times its subprocesses the same way), over that sum. Exit status 1 when
batch_1x2_warm's exceeds 5 %. Throughput per core is also given from the mappers' CPU time
(user + system, the loop's runs), which other load changes far less than the wall time.
"""

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time

try:
    from minemap.batch import batch
except ImportError:  # not installed: the source tree
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
    from minemap.batch import batch

MAX_OVERHEAD = 0.05


def timed(fn):
    """(wall seconds, seconds the mappers ran)"""
    start = time.monotonic()
    mapping = fn()
    return time.monotonic() - start, mapping


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--surveys", type=int, default=6)
    parser.add_argument("--scans", type=int, default=12)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="4 surveys of 8 scans, once")
    parser.add_argument("--out", default="out/bench-batch/batch_throughput.json")
    args = parser.parse_args()
    if args.quick:
        args.surveys, args.scans, args.repeat = 4, 8, 1
    command = os.environ.get("MINEMAP_BATCH_COMMAND", "").split() or \
        [sys.executable, "-m", "minemap"]

    from distributed import LocalCluster
    import dask

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    work = tempfile.mkdtemp(prefix="batch-throughput-")
    try:
        surveys = []
        for seed in range(1, args.surveys + 1):
            surveys.append(os.path.join(work, "surveys", f"survey{seed}"))
            subprocess.run([*command, "simulate", "--out", surveys[-1], "--scans", str(args.scans),
                            "--seed", str(seed)], check=True, stdout=subprocess.DEVNULL)

        cpu = []  # CPU seconds of the loop's mappers per survey: what a core gives, idle or not

        def sequential(out):
            mapping = 0.0
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            for s in surveys:
                mapping -= time.monotonic()
                subprocess.run([*command, "map", s, "--out", os.path.join(out, os.path.basename(s)),
                                "--threads", "2", "--quiet"], check=True)
                mapping += time.monotonic()
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append((after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
                       / len(surveys))
            return mapping

        def run_batch(out, **kwargs):
            summary = batch(surveys, out, progress=False, command=command, **kwargs)
            assert summary["totals"]["done"] == len(surveys), summary
            return sum(r["seconds"] for r in summary["surveys"])

        # Configured as batch configures the LocalCluster it starts.
        with dask.config.set({"distributed.scheduler.worker-saturation": 1.0}):
            warm = LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                dashboard_address=None)
        modes = {
            "sequential": sequential,
            "batch_1x2": lambda out: run_batch(out, workers=1, threads_per_survey=2),
            "batch_1x2_warm": lambda out: run_batch(out, scheduler=warm.scheduler_address,
                                                    threads_per_survey=2),
            "batch_2x1": lambda out: run_batch(out, workers=2, threads_per_survey=1),
        }
        runs = {name: [] for name in modes}
        try:
            for _ in range(args.repeat):
                for name, fn in modes.items():
                    out = os.path.join(work, name)
                    shutil.rmtree(out, ignore_errors=True)
                    runs[name].append(timed(lambda: fn(out)))
                    print(f"{name}: {runs[name][-1][0]:.2f} s", file=sys.stderr)
        finally:
            warm.close()
    finally:
        shutil.rmtree(work, ignore_errors=True)

    results = {}
    for name, rs in runs.items():
        wall = min(w for w, _ in rs)
        per_hour = args.surveys * 3600 / wall
        results[name] = {"wall_s": round(wall, 3), "runs_s": [round(w, 3) for w, _ in rs],
                         # the mappers' own time runs in parallel on 2x1: no overhead to take
                         "overhead": None if name == "batch_2x1" else
                         round(min((w - m) / m for w, m in rs), 4),
                         "surveys_per_hour": round(per_hour, 1),
                         "surveys_per_hour_per_core": round(per_hour / cores, 1),
                         "scans_per_hour_per_core": round(per_hour * args.scans / cores)}
    seq = results["sequential"]["wall_s"]
    report = {
        "surveys": args.surveys, "scans_per_survey": args.scans, "repeat": args.repeat,
        "cores": cores, "command": command, "modes": results,
        "overhead_ratio": round(results["batch_1x2"]["wall_s"] / seq, 4),
        "overhead_ratio_warm": round(results["batch_1x2_warm"]["wall_s"] / seq, 4),
        "cluster_start_s": round(results["batch_1x2"]["wall_s"]
                                 - results["batch_1x2_warm"]["wall_s"], 3),
        "throughput_ratio_2x1": round(seq / results["batch_2x1"]["wall_s"], 4),
        "mapper_cpu_s_per_survey": round(min(cpu), 3),
        "surveys_per_hour_per_core_from_cpu": round(3600 / min(cpu), 1),
        "scans_per_hour_per_core_from_cpu": round(3600 * args.scans / min(cpu)),
        "load_average": os.getloadavg(),
    }
    report["overhead_ok"] = results["batch_1x2_warm"]["overhead"] <= MAX_OVERHEAD
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(report, f, indent=1)
    print(json.dumps(report, indent=1))
    return 0 if report["overhead_ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
