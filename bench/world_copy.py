#!/usr/bin/env python3
"""A survey and its copies in world coordinates: do the copies map to the original's local poses?

usage: bench/world_copy.py SURVEY WORKDIR [--quantize] [--cli build/minemap]

Maps SURVEY (any folder `minemap map` reads; the defaults), exports each registered scan as a float
PLY in metres (WORKDIR/local: a PLY survey already in one frame), maps that, then writes copies of
it with an offset added in double (a UTM-size one in whole hundreds of metres, a UTM-size one that
is not, and 7 cm with no world offset) and maps each. Prints, per copy, the origin report.json
states and the worst difference between the copy's poses and the original's (conjugated by the
part of the offset the origin did not take). --quantize rounds the local coordinates to 2^-16 m
first, so the world files' doubles hold every sum exactly: what is left is the mapper's own.
Figures: docs/benchmarks.md, "Surveys in world coordinates".
"""
import argparse
import json
import pathlib
import subprocess

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
parser = argparse.ArgumentParser()
parser.add_argument("survey")
parser.add_argument("workdir")
parser.add_argument("--quantize", action="store_true")
parser.add_argument("--cli", default=str(ROOT / "build" / "minemap"))
args = parser.parse_args()
CLI, src, root = args.cli, args.survey, pathlib.Path(args.workdir)
root.mkdir(parents=True, exist_ok=True)
def run(*a):
    r = subprocess.run([CLI, *map(str, a)], capture_output=True, text=True)
    if r.returncode not in (0, 13): raise SystemExit(f"{a}: {r.returncode}\n{r.stdout}{r.stderr}")
    return r.returncode
def read_ply(p):
    b = p.read_bytes(); end = b.index(b"end_header\n") + len(b"end_header\n")
    hdr = b[:end].decode().splitlines(); n = 0; props = []
    for l in hdr:
        w = l.split()
        if w[:2] == ["element", "vertex"]: n = int(w[2])
        if w[0] == "property": props.append((w[2], {"float": "<f4", "double": "<f8", "uint": "<u4", "uchar": "u1", "ushort": "<u2", "int": "<i4"}[w[1]]))
    a = np.frombuffer(b[end:], dtype=np.dtype(props), count=n)
    return np.stack([a["x"].astype(np.float64), a["y"].astype(np.float64), a["z"].astype(np.float64)], 1)
def write_ply(p, xyz, double):
    t = "double" if double else "float"
    h = f"ply\nformat binary_little_endian 1.0\nelement vertex {len(xyz)}\nproperty {t} x\nproperty {t} y\nproperty {t} z\nend_header\n"
    p.write_bytes(h.encode() + xyz.astype("<f8" if double else "<f4").tobytes())
base = root / "base"
if not (base / "report.json").exists(): run("map", src, "--out", base, "--quiet", "--accept-doubtful")
rep = json.loads((base / "report.json").read_text())
local = root / "local"; local.mkdir(exist_ok=True)
for s in rep["scans"]:
    f = local / f"{s['name']}.ply"
    if not f.exists():
        run("export", base, "--to", root / "tmp.ply", "--scans", s["name"], "--quiet")
        xyz = read_ply(root / "tmp.ply")
        if args.quantize:
            xyz = np.round(xyz * 65536) / 65536
        write_ply(f, xyz.astype(np.float32), False)
def poses(out):
    return [np.array(s["pose"]) for s in json.loads((out / "report.json").read_text())["scans"]]
run("map", local, "--out", root / "local-out", "--quiet", "--accept-doubtful")
P0 = poses(root / "local-out")
rows = []
for name, off in [("UTM, whole 100 m", (500000.0, 6000000.0, 100.0)), ("UTM, any", (500000.37, 6000000.81, 100.23)), ("7 cm, no world offset", (0.07, 0.0, 0.0))]:
    d = root / ("copy_" + str(len(rows))); d.mkdir(exist_ok=True)
    for f in sorted(local.glob("*.ply")):
        write_ply(d / f.name, read_ply(f) + np.array(off), True)
    o = root / ("copy_" + str(len(rows)) + "-out"); rc = run("map", d, "--out", o, "--quiet", "--accept-doubtful")
    r = json.loads((o / "report.json").read_text()); origin = np.array(r.get("origin", [0, 0, 0]))
    dd = (np.array(off) - origin) * 100.0  # cm, right-handed z up (PLY survey frame)
    worst_t = worst_r = 0.0
    for a, b in zip(P0, poses(o)):
        exp_t = a[:3, 3] + dd - a[:3, :3] @ dd
        worst_t = max(worst_t, np.linalg.norm(b[:3, 3] - exp_t))
        c = np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1); worst_r = max(worst_r, np.degrees(np.arccos(c)))
    rows.append((name, off, list(origin), rc, worst_t * 10, worst_r))
    print(f"{name} {off}: origin {list(origin)} exit {rc}: worst pose {worst_t*10:.6f} mm, {worst_r:.6f} deg", flush=True)
