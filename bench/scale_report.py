#!/usr/bin/env python3
"""The table and the plot of bench/scale.sh: surveys of any length on one machine.

usage: scale_report.py --out DIR TAG=REPORT_JSON=TIME_FILE ...

TIME_FILE holds GNU time's "%e %M" (wall seconds, peak resident KB). Writes DIR/scale.json (each
run's figures and per-scan series), DIR/scale.md (the table for docs/scaling.md) and DIR/scale.svg:
the time each scan cost when it arrived (a running median over 51 scans) and the process's resident
memory as it was matched, against the scan's index, one line per run. Plain SVG: no dependencies.
"""
import argparse
import json
import os
import statistics

COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]


def running_median(values, half=25):
    out = []
    for i in range(len(values)):
        window = values[max(0, i - half):i + half + 1]
        out.append(statistics.median(window))
    return out


def summarise(tag, report_path, time_path):
    with open(report_path) as f:
        report = json.load(f)
    with open(time_path) as f:
        # GNU time's "%e %M" line; a run that exited non-zero (13: doubtful scans) has
        # "Command exited with non-zero status N" on the line before it.
        wall_s, peak_kb = f.read().strip().splitlines()[-1].split()[:2]
    timings = report["timings_s"]
    per_scan = timings.get("per_scan", [])
    memory = report.get("memory_mb", {}).get("per_scan", [])
    quarter = max(1, len(per_scan) // 4)
    first = statistics.mean(per_scan[1:1 + quarter]) if len(per_scan) > 1 else 0.0  # scan 0 is the master
    last = statistics.mean(per_scan[-quarter:]) if per_scan else 0.0
    truth = report.get("truth", {}).get("registered", {})
    points = sum(s.get("points_in", 0) for s in report["scans"])
    loops = report.get("loop_closures", [])
    return {
        "tag": tag,
        "scans": len(report["scans"]),
        "points": points,
        "wall_s": float(wall_s),
        "peak_rss_mb": int(peak_kb) / 1024.0,
        "spilled_mb": report.get("memory_mb", {}).get("spilled"),
        "load_s": timings.get("load", 0.0),
        "matching_s": timings.get("pairwise", 0.0) + timings.get("relaxation", 0.0),
        "filter_s": timings.get("filter", 0.0),
        "tree_build_s": timings.get("tree_build", 0.0),
        "loop_closure_s": timings.get("loop_closure", 0.0),
        "write_s": timings.get("write", 0.0),
        "per_scan_first_quarter_s": first,
        "per_scan_last_quarter_s": last,
        "flatness": last / first if first > 0 else None,
        "rss_at_quarter_mb": memory[len(memory) // 4] if memory else None,
        "rss_at_end_mb": memory[-1] if memory else None,
        "loops_tried": len(loops),
        "loops_closed": sum(1 for loop in loops if loop.get("closed")),
        "doubtful": len(report.get("doubtful_scans", [])),
        "mean_error_percent": truth.get("mean_translation_percent_of_path"),
        "per_scan_s": per_scan,
        "memory_mb": memory,
    }


def polyline(xs, ys, x_of, y_of, colour, most=1500):
    # At most `most` vertices a line (every k-th scan): the page stays small for 10 000 scans.
    xs, ys = list(xs), list(ys)
    step = max(1, len(xs) // most)
    points = " ".join(f"{x_of(x):.0f},{y_of(y):.1f}" for x, y in zip(xs[::step], ys[::step]))
    return f'<polyline fill="none" stroke="{colour}" stroke-width="1.2" points="{points}"/>'


def panel(runs, key, smooth, title, unit, top):
    """One plot: `key`'s series of every run against the scan index, at `top` px from the top."""
    left, width, height = 70, 820, 220
    series = [(r, running_median(r[key]) if smooth else r[key]) for r in runs if r[key]]
    x_max = max((len(s) for _, s in series), default=1)
    y_max = max((max(s) for _, s in series), default=1.0) * 1.1 or 1.0
    x_of = lambda x: left + width * x / max(1, x_max - 1)
    y_of = lambda y: top + height - height * y / y_max
    parts = [f'<text x="{left}" y="{top - 8}" font-size="13">{title}</text>',
             f'<rect x="{left}" y="{top}" width="{width}" height="{height}" fill="none" stroke="#888"/>']
    for k in range(5):
        value = y_max * k / 4
        parts.append(f'<text x="{left - 6}" y="{y_of(value) + 4:.1f}" font-size="11" text-anchor="end">'
                     f'{value:.3g}</text>')
    for k in range(5):
        index = round((x_max - 1) * k / 4)
        parts.append(f'<text x="{x_of(index):.1f}" y="{top + height + 14}" font-size="11" text-anchor="middle">'
                     f'{index}</text>')
    parts.append(f'<text x="{left + width / 2}" y="{top + height + 30}" font-size="11" text-anchor="middle">'
                 f'scan index</text>')
    parts.append(f'<text x="14" y="{top + height / 2}" font-size="11" transform="rotate(-90 14 {top + height / 2})"'
                 f' text-anchor="middle">{unit}</text>')
    for (run, values), colour in zip(series, COLOURS * 4):
        parts.append(polyline(range(len(values)), values, x_of, y_of, colour))
    return parts


def write_svg(path, runs):
    parts = ['<svg xmlns="http://www.w3.org/2000/svg" width="920" height="620" font-family="sans-serif">',
             '<rect width="100%" height="100%" fill="white"/>']
    parts += panel(runs, "per_scan_s", True, "time each scan cost when it arrived (running median of 51)", "s", 40)
    parts += panel(runs, "memory_mb", False, "resident memory as each scan was matched", "MB", 340)
    for k, (run, colour) in enumerate(zip(runs, COLOURS * 4)):
        parts.append(f'<text x="{700}" y="{60 + 16 * k}" font-size="12" fill="{colour}">{run["tag"]}</text>')
    parts.append("</svg>")
    with open(path + ".tmp", "w") as f:
        f.write("\n".join(parts) + "\n")
    os.replace(path + ".tmp", path)


def table(runs):
    lines = ["| survey | scans | points | wall | per scan, first / last quarter | read | matching | loops | write "
             "| peak RSS | RSS at 1/4, end of matching | spilled | mean error |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        error = f'{r["mean_error_percent"]:.3f} % of the path' if r["mean_error_percent"] is not None else "-"
        quarter = f'{r["rss_at_quarter_mb"]:.0f} / {r["rss_at_end_mb"]:.0f} MB' if r["memory_mb"] else "-"
        loops = f'{r["loop_closure_s"]:.1f} s ({r["loops_closed"]}/{r["loops_tried"]} closed)'
        spilled = f'{r["spilled_mb"]:.0f} MB' if r["spilled_mb"] is not None else "-"
        lines.append(
            f'| {r["tag"]} | {r["scans"]} | {r["points"] / 1e6:.0f} M | {r["wall_s"]:.0f} s '
            f'| {1000 * r["per_scan_first_quarter_s"]:.1f} / {1000 * r["per_scan_last_quarter_s"]:.1f} ms '
            f'| {r["load_s"]:.0f} s | {r["matching_s"]:.0f} s | {loops} | {r["write_s"]:.1f} s '
            f'| {r["peak_rss_mb"] / 1024:.2f} GB | {quarter} | {spilled} | {error} |')
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("runs", nargs="+", help="TAG=REPORT_JSON=TIME_FILE")
    args = parser.parse_args()
    runs = []
    for spec in args.runs:
        tag, report, time_file = spec.split("=", 2)
        if os.path.exists(report) and os.path.exists(time_file):
            runs.append(summarise(tag, report, time_file))
    with open(os.path.join(args.out, "scale.json"), "w") as f:
        json.dump(runs, f, indent=1)
    with open(os.path.join(args.out, "scale.md"), "w") as f:
        f.write(table(runs))
    write_svg(os.path.join(args.out, "scale.svg"), runs)
    print(table(runs), end="")


if __name__ == "__main__":
    main()
