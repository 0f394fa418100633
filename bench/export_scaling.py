#!/usr/bin/env python3
"""`minemap export` at full density as the survey grows: peak memory and time per point.

usage: bench/export_scaling.py [--scans 200,500,1000] [--formats ply,laz,copc.laz] [--out DIR]
                               [--python build/venv/bin/python] [--cli build/minemap] [--keep]
       bench/export_scaling.py --plot A.json,B.json --out DIR   (draw merged runs only)

For each size, `minemap simulate --scans N` writes the drive (123 046 points a scan), `minemap map`
maps it (the default), then each format is exported from OUT to a file at full density: .ply by the
C++ program, .laz and .copc.laz by the package (`python -m minemap export`), each under
/usr/bin/time -v (its peak resident memory) and a wall clock. The exported file is opened again to
count its points (laspy for LAS/COPC, the PLY header), which must equal the map's sum of points_in;
COPC files are also queried (laspy's CopcReader, a box around the first scan). Writes
OUT/export_scaling.json and OUT/export_scaling.svg (time per point and peak memory against the
survey's points). Disk: about 60 bytes a point for the survey and the files at once (1000 scans:
7 GB); the exports are deleted after counting unless --keep.
"""
import argparse
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]


def timed(command):
    """(wall s, peak RSS MB, stdout+stderr) of `command` under /usr/bin/time -v."""
    start = time.monotonic()
    result = subprocess.run(["/usr/bin/time", "-v", *command], capture_output=True, text=True)
    wall = time.monotonic() - start
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, command))} exited {result.returncode}:\n{result.stdout}{result.stderr}")
    rss_kb = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", result.stderr).group(1))
    return wall, rss_kb / 1024.0, result.stdout + result.stderr


def count_points(path, python):
    if path.suffix == ".ply":
        with open(path, "rb") as f:
            header = f.read(4096).split(b"end_header")[0].decode(errors="replace")
        return int(re.search(r"element vertex (\d+)", header).group(1))
    code = ("import laspy,sys,numpy as np\n"
            "p=sys.argv[1]\n"
            "if p.endswith('.copc.laz'):\n"
            "    r=laspy.CopcReader.open(p); h=r.header\n"
            "    box=r.query(bounds=laspy.Bounds(mins=np.array(h.mins), maxs=(np.array(h.mins)+np.array(h.maxs))/2))\n"
            "    print(h.point_count, len(box))\n"
            "else:\n"
            "    print(laspy.open(p).header.point_count, 0)\n")
    out = subprocess.run([python, "-c", code, str(path)], capture_output=True, text=True, check=True).stdout.split()
    return int(out[0])


def plot(rows, formats, svg):
    """Time per point and peak memory against the survey's points, one line per format."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no plot", file=sys.stderr)
        return
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    for fmt in formats:
        mine = sorted((r for r in rows if r["format"] == fmt), key=lambda r: r["points"])
        left.plot([r["points"] / 1e6 for r in mine], [r["ns_per_point"] for r in mine], "o-", label=fmt)
        right.plot([r["points"] / 1e6 for r in mine], [r["peak_rss_mb"] for r in mine], "o-", label=fmt)
    left.set(xlabel="survey points (millions)", ylabel="time per point (ns)", title="export: time per point")
    right.set(xlabel="survey points (millions)", ylabel="peak RSS (MB)", title="export: peak memory")
    left.set_ylim(bottom=0)
    right.set_ylim(bottom=0)
    for axes in (left, right):
        axes.grid(alpha=0.3)
        axes.legend()
    fig.tight_layout()
    fig.savefig(svg)
    print(f"wrote {svg}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scans", default="200,500,1000")
    parser.add_argument("--formats", default="ply,laz,copc.laz")
    parser.add_argument("--out", default="out/bench/export_scaling")
    parser.add_argument("--python", default=str(ROOT / "build" / "venv" / "bin" / "python"))
    parser.add_argument("--cli", default=str(ROOT / "build" / "minemap"))
    parser.add_argument("--keep", action="store_true")
    parser.add_argument("--plot", metavar="JSON", help="only draw OUT/export_scaling.svg from these rows "
                        "(export_scaling.json files, comma-separated: runs of different sizes merged)")
    args = parser.parse_args()
    out = pathlib.Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    if args.plot:
        rows = [row for path in args.plot.split(",") for row in json.loads(pathlib.Path(path).read_text())]
        plot(rows, args.formats.split(","), out / "export_scaling.svg")
        return 0
    rows = []
    for n in [int(s) for s in args.scans.split(",")]:
        survey, mapped = out / f"survey{n}", out / f"map{n}"
        if not (survey / "scan000.3d").exists():
            subprocess.run([args.cli, "simulate", "--out", str(survey), "--scans", str(n)], check=True,
                           capture_output=True)
        if not (mapped / "report.json").exists():
            subprocess.run([args.cli, "map", str(survey), "--out", str(mapped), "--quiet", "--accept-doubtful"],
                           check=True, capture_output=True)
        report = json.loads((mapped / "report.json").read_text())
        points = sum(s["points_in"] for s in report["scans"])
        for fmt in args.formats.split(","):
            target = out / f"export{n}.{fmt}"
            command = ([args.cli] if fmt == "ply" else [args.python, "-m", "minemap"]) + \
                      ["export", str(mapped), "--to", str(target), "--quiet"]
            wall, rss_mb, _ = timed(command)
            written = count_points(target, args.python)
            if written != points:
                raise SystemExit(f"{target}: {written} points, the map read {points}")
            size_mb = target.stat().st_size / 1e6
            row = {"scans": n, "points": points, "format": fmt, "wall_s": round(wall, 2),
                   "ns_per_point": round(1e9 * wall / points, 1), "peak_rss_mb": round(rss_mb, 1),
                   "file_mb": round(size_mb, 1)}
            rows.append(row)
            print(json.dumps(row), flush=True)
            if not args.keep:
                target.unlink()
    (out / "export_scaling.json").write_text(json.dumps(rows, indent=1) + "\n")
    plot(rows, args.formats.split(","), out / "export_scaling.svg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
