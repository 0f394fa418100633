#!/usr/bin/env python3
"""Plots the cost of each new scan against its index (bench/time_per_scan.sh writes the inputs).

usage: plot_time_per_scan.py --out DIR NAME=REPORT_JSON=START_S=END_S ...

Reads each run's report.json ("timings_s"."per_scan": seconds spent when each scan arrived) and
writes DIR/time_per_scan.json (per run: wall time, stage totals, the per-scan series, the mean cost
of the first and last quarter of the survey and their ratio, which is about 1 when the cost per scan
stays flat) and DIR/time_per_scan.svg (matplotlib, when it is installed).
"""
import argparse
import json
import os
import statistics
import sys


def summarise(name, report_path, start_s, end_s):
    with open(report_path) as f:
        report = json.load(f)
    # An older minemap (--baseline) has no per-scan figures: its totals only.
    per_scan = report["timings_s"].get("per_scan", [])
    quarter = max(1, len(per_scan) // 4)
    first = statistics.mean(per_scan[1:1 + quarter]) if per_scan else None  # scan 0 is the master
    last = statistics.mean(per_scan[-quarter:]) if per_scan else None
    truth = report.get("truth", {}).get("registered", {})
    return {
        "name": name,
        "wall_s": end_s - start_s,
        "mode": report["mode"],
        "scans": len(per_scan),
        "relaxation_matches": report["relaxation_matches"],
        "timings_s": {k: v for k, v in report["timings_s"].items() if k != "per_scan"},
        "mean_per_scan_s_first_quarter": first,
        "mean_per_scan_s_last_quarter": last,
        "last_over_first": last / first if first else None,
        "mean_translation_error": truth.get("mean_translation"),
        "unit": report.get("unit"),
        "per_scan_s": per_scan,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("runs", nargs="+", help="NAME=REPORT_JSON=START_S=END_S")
    args = parser.parse_args()
    runs = []
    for run in args.runs:
        name, path, start, end = run.split("=")
        runs.append(summarise(name, path, float(start), float(end)))
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "time_per_scan.json"), "w") as f:
        json.dump(runs, f, indent=2)
    for r in runs:
        error = r["mean_translation_error"]
        line = (f"{r['name']:13s} wall {r['wall_s']:7.1f} s  pairwise {r['timings_s']['pairwise']:6.1f} s  relaxation "
                f"{r['timings_s']['relaxation']:7.1f} s ({r['relaxation_matches']} matches)  loops "
                f"{r['timings_s'].get('loop_closure', 0.0):5.1f} s")
        if r["per_scan_s"]:
            line += (f"  per scan: first quarter {r['mean_per_scan_s_first_quarter']:.3f} s, last quarter "
                     f"{r['mean_per_scan_s_last_quarter']:.3f} s (x{r['last_over_first']:.2f})")
        if error is not None:
            line += f"  mean error {error:.1f} {r['unit']}"
        print(line)
    try:
        import matplotlib
    except ImportError:
        print("plot_time_per_scan: matplotlib is missing (apt-get install python3-matplotlib): no plot", file=sys.stderr)
        return
    matplotlib.use("Agg")
    matplotlib.rcParams["svg.hashsalt"] = "minemap"  # the same file for the same figures
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for r in (r for r in runs if r["per_scan_s"]):
        ax.plot(range(len(r["per_scan_s"])), r["per_scan_s"], label=f"{r['name']} ({r['wall_s']:.0f} s in all)",
                linewidth=1)
    ax.set_xlabel("scan index")
    ax.set_ylabel("seconds when the scan arrived")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    ax.set_title("minemap: cost of each new scan")
    fig.tight_layout()
    fig.savefig(os.path.join(args.out, "time_per_scan.svg"), metadata={"Date": None})
    print(f"wrote {args.out}/time_per_scan.svg and time_per_scan.json")


if __name__ == "__main__":
    main()
