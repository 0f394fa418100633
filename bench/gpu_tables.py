#!/usr/bin/env python3
"""Turns the results of bench/run_gpu.sh into Markdown: one row per survey and backend (wall time,
peak RSS, the stages' times from report.json's timings_s, the exit status) and whether the two
backends' poses agree bit for bit.

usage: bench/gpu_tables.py RESULTS_DIR   (the folder inside OUT/gpu-results.tar.gz)
"""
import json
import pathlib
import re
import sys

STAGES = ("load", "filter", "tree_build", "pairwise", "relaxation", "loop_closure", "write")


def time_v(text):
    """Wall seconds and peak RSS (MB) from /usr/bin/time -v's report."""
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (?:(\d+):)?(\d+):([\d.]+)", text)
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", text)
    seconds = None
    if wall:
        seconds = int(wall.group(1) or 0) * 3600 + int(wall.group(2)) * 60 + float(wall.group(3))
    return seconds, (int(rss.group(1)) / 1024 if rss else None)


def main():
    results = pathlib.Path(sys.argv[1])
    agree = {}
    for line in (results / "poses_agree.tsv").read_text().splitlines():
        name, verdict = line.split("\t")
        agree[name] = verdict
    exits = {}
    for line in (results / "stages.tsv").read_text().splitlines():
        name, rc, _ = line.split("\t")
        exits[name] = rc
    print("| survey | backend | wall | peak RSS | " + " | ".join(STAGES) + " | exit | poses cpu = opencl |")
    print("|---" * (len(STAGES) + 6) + "|")
    for name in agree:
        for backend in ("cpu", "opencl"):
            console = results / f"map-{name}-{backend}.txt"
            report = results / f"map-{name}-{backend}.report.json"
            wall, rss = time_v(console.read_text()) if console.exists() else (None, None)
            timings = json.loads(report.read_text()).get("timings_s", {}) if report.exists() else {}
            cells = [f"{timings[s]:.2f}" if s in timings else "" for s in STAGES]
            print(f"| {name} | {backend} | {wall:.2f} s | {rss:.0f} MB | " + " | ".join(cells) +
                  f" | {exits.get(f'map-{name}-{backend}', '?')} | {agree[name] if backend == 'opencl' else ''} |")


if __name__ == "__main__":
    main()
