#!/usr/bin/env python3
"""Does `minemap watch` keep up with a robot? A simulated survey (the paper's scanner: a tilting
2D laser, one scan per stop) is fed into a folder scan by scan, as a robot writes it (points, then
the pose file), every --interval-s seconds, while `minemap watch` maps it; each scan's cost is what
watch spent on it when it arrived (read + match + rewriting every output), from its log lines. The
margin is the paper's time per stop (about 20 s: the 3D scan takes most of it) over the slowest
scan's cost: above 1, the map is complete before the next scan lands. Each configuration runs in
turn, in one run (the machine's noise hits them alike).

usage: bench/watch_margin.py [--scans 40] [--threads 2] [--interval-s 1.0] [--stop-s 20]
                             [--configs "default simultaneous"] [--cli build/minemap]
                             [--out out/bench/watch_margin.json]
"""
import argparse
import json
import platform
import re
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CONFIGS = {"default": [], "simultaneous": ["--preset", "simultaneous"]}
LINE = re.compile(r"^(scan\d+): read ([\d.]+) s, matched ([\d.]+) s, outputs ([\d.]+) s")


def run_config(cli: Path, source: Path, work: Path, name: str, args, scans: int, threads: int, interval_s: float):
    folder, out = work / f"{name}-survey", work / f"{name}-out"
    folder.mkdir()
    (folder / "truth").mkdir()
    watch = subprocess.Popen([str(cli), "watch", str(folder), "--out", str(out), "--scans", str(scans), "--threads",
                              str(threads), "--poll-ms", "50", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    start = time.monotonic()
    for k in range(scans):
        scan = f"scan{k:03d}"
        shutil.copy(source / f"{scan}.3d", folder / f"{scan}.3d")
        shutil.copy(source / "truth" / f"{scan}.pose", folder / "truth" / f"{scan}.pose")
        shutil.copy(source / f"{scan}.pose", folder / f"{scan}.pose")
        time.sleep(max(0.0, start + (k + 1) * interval_s - time.monotonic()))
    stdout, stderr = watch.communicate(timeout=3600)
    if watch.returncode not in (0, 13):
        raise SystemExit(f"watch ({name}) exited {watch.returncode}:\n{stderr}")
    per_scan = []
    for line in stdout.splitlines():
        if m := LINE.match(line):
            per_scan.append({"scan": m[1], "read_s": float(m[2]), "match_s": float(m[3]), "outputs_s": float(m[4])})
    for s in per_scan:
        s["total_s"] = s["read_s"] + s["match_s"] + s["outputs_s"]
    report = json.loads((out / "report.json").read_text())
    totals = [s["total_s"] for s in per_scan]
    return {"config": name, "args": args, "scans": len(per_scan), "points_per_scan": None,
            "median_s": statistics.median(totals), "max_s": max(totals),
            "median_match_s": statistics.median(s["match_s"] for s in per_scan),
            "median_outputs_s": statistics.median(s["outputs_s"] for s in per_scan),
            "last_scan_s": totals[-1], "error_cm": report.get("truth", {}).get("registered", {}).get("mean_translation"),
            "per_scan": per_scan}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scans", type=int, default=40)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--interval-s", type=float, default=1.0, help="feed one scan every this many seconds")
    parser.add_argument("--stop-s", type=float, default=20.0, help="the robot's time per stop (the paper: ~20 s)")
    parser.add_argument("--configs", default="default simultaneous")
    parser.add_argument("--cli", type=Path, default=REPO / "build" / "minemap")
    parser.add_argument("--out", type=Path, default=REPO / "out" / "bench" / "watch_margin.json")
    a = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="minemap-watch-") as tmp:
        work = Path(tmp)
        source = work / "source"
        subprocess.run([str(a.cli), "simulate", "--out", str(source), "--scans", str(a.scans)], check=True,
                       capture_output=True)
        points = sum(1 for line in (source / "scan000.3d").open() if line[:1] not in ("#", ""))
        results = []
        for name in a.configs.split():
            r = run_config(a.cli, source, work, name, CONFIGS[name], a.scans, a.threads, a.interval_s)
            r["points_per_scan"] = points
            r["margin"] = a.stop_s / r["max_s"]
            results.append(r)
            print(f"{name:13s} {r['scans']} scans of {points} points: per scan median {r['median_s']:.2f} s "
                  f"(match {r['median_match_s']:.2f} s, outputs {r['median_outputs_s']:.2f} s), max {r['max_s']:.2f} s,"
                  f" last {r['last_scan_s']:.2f} s; margin {r['margin']:.1f}x against {a.stop_s:g} s per stop; "
                  f"error {r['error_cm']:.1f} cm")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps({"machine": platform.node(), "cores_used": a.threads, "stop_s": a.stop_s,
                                 "interval_s": a.interval_s, "results": results}, indent=1) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
