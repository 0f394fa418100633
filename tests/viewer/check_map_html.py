#!/usr/bin/python3
"""map.html in a real browser: headless Chromium opens the page from disk and must render it.

Test (CTest's viewer_map_html): simulates a 6-scan survey with 4 control stations with the built
CLI, maps it tied to them, then opens OUT/map.html in Debian's chromium twice, off the network,
with WebGL on SwiftShader (the CPU):
  1. --dump-dom of map.html#scan=<a scan>: the title says "rendered N points" with N > 0, the
     info box shows that scan's name, ICP figures and sigma, and the sigma legend is there;
  2. --screenshot: the middle of the picture (where no panel is) shows the map: over 1 % of its
     pixels differ from the background, in several colours.
Neither run may print a console message (the page prints none on success). A missing chromium is
a failure, never a skip. With --survey DIR (a survey whose scans carry intensities, e.g. the shared
mine data) it maps that survey instead, opens the page at its first scan, and the page must also
colour by intensity: the intensity choice shown and chosen, and the colour bar labelled.

Measure (--measure PAGE): opens an existing page RUNS times and prints its size, the time to its
first render that the page reports (from navigation start) and the browser's wall time.

Standard library only: Debian's /usr/bin/python3 runs it.
"""
import argparse
import os
import re
import shutil
import statistics
import struct
import subprocess
import sys
import tempfile
import time
import zlib

BACKGROUND = (0x15, 0x18, 0x1C)  # the page's background (map_html.cpp)
WINDOW = (1024, 768)
# WebGL in headless Chromium without a GPU: ANGLE on SwiftShader, which newer Chromium allows
# only when asked to (--enable-unsafe-swiftshader).
CHROMIUM_FLAGS = [
    "--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--no-first-run", "--no-default-browser-check", "--disable-extensions", "--disable-sync",
    "--disable-background-networking", "--disable-component-update", "--hide-scrollbars",
    "--mute-audio", "--enable-logging=stderr", "--v=0",
]


class CheckFailed(Exception):
    pass


def run_chromium(chromium, url, extra, profile, timeout_s):
    """Runs chromium on `url`; returns (stdout, console lines, wall seconds)."""
    command = [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
               f"--window-size={WINDOW[0]},{WINDOW[1]}", *extra, url]
    start = time.monotonic()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired as e:
        raise CheckFailed(f"chromium did not finish within {timeout_s} s: {' '.join(command)}") from e
    wall_s = time.monotonic() - start
    if done.returncode != 0:
        raise CheckFailed(f"chromium exited {done.returncode}:\n{done.stderr[-4000:]}")
    # Every console message (log, warning, error, uncaught exception) is logged as INFO:CONSOLE.
    console = [line for line in done.stderr.splitlines() if re.search(r":CONSOLE[:(]", line)]
    return done.stdout, console, wall_s


def page_title(dom):
    m = re.search(r"<title>(.*?)</title>", dom, re.S)
    return m.group(1) if m else ""


def rendered(title):
    m = re.match(r"minemap map: rendered (\d+) points in (\d+) ms", title)
    return (int(m.group(1)), int(m.group(2))) if m else None


def read_png(path):
    """(width, height, rows of (r, g, b) tuples) of an 8-bit RGB or RGBA PNG."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise CheckFailed(f"{path} is not a PNG")
    pos, idat, header = 8, b"", None
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    width, height, depth, colour, _, _, interlace = header
    if depth != 8 or colour not in (2, 6) or interlace != 0:
        raise CheckFailed(f"{path}: unexpected PNG format (depth {depth}, colour type {colour}, interlace {interlace})")
    bpp = 3 if colour == 2 else 4
    raw = zlib.decompress(idat)
    stride = width * bpp
    previous = bytearray(stride)
    rows = []
    for y in range(height):
        kind = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):  # undo the PNG filter (none, sub, up, average, Paeth)
            a = line[i - bpp] if i >= bpp else 0
            b = previous[i]
            c = previous[i - bpp] if i >= bpp else 0
            if kind == 1:
                line[i] = (line[i] + a) & 255
            elif kind == 2:
                line[i] = (line[i] + b) & 255
            elif kind == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append([tuple(line[x * bpp:x * bpp + 3]) for x in range(width)])
        previous = line
    return width, height, rows


def check_screenshot(path):
    """The middle half of the picture (no panel there) must show the map."""
    width, height, rows = read_png(path)
    region = [px for row in rows[height // 4:3 * height // 4] for px in row[width // 4:3 * width // 4]]
    differing = [px for px in region if sum(abs(p - q) for p, q in zip(px, BACKGROUND)) > 30]
    fraction = len(differing) / len(region)
    colours = {(r >> 4, g >> 4, b >> 4) for r, g, b in differing}
    print(f"screenshot {width}x{height}: {100 * fraction:.1f} % of the middle is map, {len(colours)} colours")
    if fraction < 0.01:
        raise CheckFailed(f"the screenshot shows no map: {100 * fraction:.2f} % of its middle differs from the background")
    if len(colours) < 5:
        raise CheckFailed(f"the screenshot shows only {len(colours)} colours where the map should be")


def run_test(args, chromium):
    work = tempfile.mkdtemp(prefix="minemap-viewer-")
    try:
        # Tied to control (4 stations), so the page also shows each scan's sigma.
        commands = [["simulate", "--out", f"{work}/survey", "--scans", str(args.scans), "--control", "4"],
                    ["map", f"{work}/survey", "--out", f"{work}/out", "--threads", "2",
                     "--control", f"{work}/survey/control.txt"]]
        if args.survey:
            commands = [["map", args.survey, "--out", f"{work}/out", "--threads", "2", "--accept-doubtful"]]
        for command in commands:
            done = subprocess.run([args.cli, *command], capture_output=True, text=True)
            if done.returncode != 0:
                raise CheckFailed(f"minemap {' '.join(command)} exited {done.returncode}:\n{done.stdout}{done.stderr}")
        page = f"{work}/out/map.html"
        if not os.path.isfile(page):
            raise CheckFailed("minemap map wrote no map.html")
        print(f"map.html: {os.path.getsize(page) / 1e6:.2f} MB")
        url = "file://" + page

        scan = "scan002"
        if args.survey:
            report = open(f"{work}/out/report.json").read()
            scan = re.search(r'"name": "([^"]+)"', report).group(1)
        dom, console, wall_s = run_chromium(chromium, url + "#scan=" + scan, ["--dump-dom"], f"{work}/profile",
                                            args.timeout)
        title = page_title(dom)
        figures = rendered(title)
        print(f"title: {title!r} (chromium {wall_s:.1f} s)")
        if console:
            raise CheckFailed("the page wrote to the console:\n" + "\n".join(console))
        if not figures or figures[0] <= 0:
            raise CheckFailed(f"the page did not render points; its title is {title!r}")
        info = re.search(r'<div id="info"[^>]*>(.*?)</div>\s*<div id="failure"', dom, re.S)
        info_text = re.sub(r"<[^>]+>", " ", info.group(1)) if info else ""
        if scan not in info_text or "ICP iterations" not in info_text or "rms" not in info_text:
            raise CheckFailed(f"map.html#scan={scan} shows no figures for {scan}: {info_text!r}")
        if not args.survey:
            sigma = re.search(r'<div id="sigma-legend"[^>]*>(.*?)</div>', dom, re.S)
            if "tied to control" not in info_text or not sigma or "sigma 0 to" not in sigma.group(1):
                raise CheckFailed(f"a map tied to control shows no sigma: info {info_text!r}, "
                                  f"legend {sigma and sigma.group(1)!r}")
            print(f"sigma: {sigma.group(1)}")
        if args.survey:
            choice = re.search(r'<label id="intensity-choice"([^>]*)>', dom)
            legend = re.search(r'<div id="legend"[^>]*>(.*?)</div>', dom, re.S)
            ends = re.search(r'<span id="colour-lo">([^<]*)</span><span id="colour-hi">([^<]*)</span>', dom)
            if not choice or "hidden" in choice.group(1):
                raise CheckFailed("the page offers no intensity colouring for a survey with intensities")
            if not legend or "intensity" not in legend.group(1) or not ends or not ends.group(1) or not ends.group(2):
                raise CheckFailed(f"the page does not colour by intensity with a labelled bar: {legend and legend.group(1)!r}")
            print(f"intensity colouring, bar {ends.group(1)} .. {ends.group(2)}")

        shot = f"{work}/screenshot.png"
        _, console, wall_s = run_chromium(chromium, url, [f"--screenshot={shot}"], f"{work}/profile", args.timeout)
        if console:
            raise CheckFailed("the page wrote to the console:\n" + "\n".join(console))
        if not os.path.isfile(shot):
            raise CheckFailed("chromium wrote no screenshot")
        check_screenshot(shot)
        if args.keep:
            shutil.copy(shot, args.keep)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def measure(args, chromium):
    page = os.path.abspath(args.measure)
    print(f"{page}: {os.path.getsize(page) / 1e6:.1f} MB")
    first_render_ms, wall = [], []
    with tempfile.TemporaryDirectory(prefix="minemap-viewer-") as profile:
        for run in range(args.runs):
            dom, console, wall_s = run_chromium(chromium, "file://" + page, ["--dump-dom"], profile, args.timeout)
            figures = rendered(page_title(dom))
            if console or not figures:
                raise CheckFailed(f"run {run}: title {page_title(dom)!r}, console: {console}")
            first_render_ms.append(figures[1])
            wall.append(wall_s)
            print(f"run {run}: {figures[0]} points, first render at {figures[1]} ms, chromium {wall_s:.2f} s")
    print(f"median: first render at {statistics.median(first_render_ms):.0f} ms, chromium {statistics.median(wall):.2f} s")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cli", help="the minemap program (the test)")
    parser.add_argument("--scans", type=int, default=6)
    parser.add_argument("--survey", help="map this survey (with intensities) instead of a simulated one")
    parser.add_argument("--chromium", default="chromium")
    parser.add_argument("--timeout", type=int, default=90, help="seconds per chromium run")
    parser.add_argument("--keep", help="copy the screenshot here")
    parser.add_argument("--measure", metavar="PAGE", help="time an existing map.html instead")
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    chromium = shutil.which(args.chromium)
    try:
        if not chromium:
            raise CheckFailed(f"no {args.chromium} on PATH: install Debian's chromium (scripts/install-deps.sh test)")
        if args.measure:
            measure(args, chromium)
        elif args.cli:
            run_test(args, chromium)
        else:
            parser.error("--cli or --measure is required")
    except CheckFailed as e:
        print(f"check_map_html: FAILED: {e}", file=sys.stderr)
        return 1
    print("check_map_html: passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
