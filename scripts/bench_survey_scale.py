"""Survey planning time against input size; see bench-survey-scale.sh."""

import argparse
import json
import math
import os
import random
import subprocess
import tempfile
import time
from pathlib import Path

LAT0, LON0 = 47.0, 8.5
M_LAT = 111_320.0
M_LON = 111_320.0 * math.cos(math.radians(LAT0))
BINARY = Path(os.environ.get("CARGO_TARGET_DIR", "target")) / "release" / "terraplan"


def lonlat(x, y):
    return [LON0 + x / M_LON, LAT0 + y / M_LAT]


def polygon(points):
    ring = [lonlat(x, y) for x, y in points]
    return {"type": "Polygon", "coordinates": [ring + [ring[0]]]}


def round_field(vertices, radius=1000.0):
    return polygon(
        [(radius * math.cos(2 * math.pi * i / vertices),
          radius * math.sin(2 * math.pi * i / vertices)) for i in range(vertices)]
    )


def square_field(side=2000.0):
    h = side / 2
    return polygon([(-h, -h), (h, -h), (h, h), (-h, h)])


def hexagon_zones(count, spread=900.0):
    rnd = random.Random(count)
    features = []
    for _ in range(count):
        cx, cy, r = rnd.uniform(-spread, spread), rnd.uniform(-spread, spread), rnd.uniform(1, 4)
        hexagon = [(cx + r * math.cos(math.pi * k / 3), cy + r * math.sin(math.pi * k / 3))
                   for k in range(6)]
        features.append({"type": "Feature", "properties": {}, "geometry": polygon(hexagon)})
    return {"type": "FeatureCollection", "features": features}


def plan(work, roi, zones, timeout):
    work.mkdir(parents=True, exist_ok=True)
    (work / "roi.geojson").write_text(json.dumps(roi))
    (work / "params.json").write_text(json.dumps(
        {"altitude_m": 120, "uavs": [{"id": "u", "start": [LON0, LAT0 - 1200 / M_LAT]}]}))
    args = [str(BINARY), "survey", "--roi", str(work / "roi.geojson"),
            "--params", str(work / "params.json"), "--out", str(work / "out"),
            "--timeout-s", str(timeout)]
    if zones is not None:
        (work / "zones.geojson").write_text(json.dumps(zones))
        args += ["--no-fly", str(work / "zones.geojson")]
    began = time.perf_counter()
    run = subprocess.run(args, capture_output=True, text=True)
    took = time.perf_counter() - began
    return took if run.returncode == 0 else None, run.stderr.strip().splitlines()[-1:] or [""]


def slope(points):
    pts = [(math.log(n), math.log(t)) for n, t in points if t]
    if len(pts) < 2:
        return float("nan")
    mx = sum(x for x, _ in pts) / len(pts)
    my = sum(y for _, y in pts) / len(pts)
    return sum((x - mx) * (y - my) for x, y in pts) / sum((x - mx) ** 2 for x, _ in pts)


def series(name, sizes, make, timeout):
    print(f"\n{name}")
    print(f"{'size':>8} {'seconds':>9}")
    points = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            roi, zones = make(n)
            took, last = plan(Path(tmp) / str(n), roi, zones, timeout)
            points.append((n, took))
            shown = f"{took:9.2f}" if took is not None else f"{'failed':>9}  {last[0]}"
            print(f"{n:>8} {shown}", flush=True)
    s = slope(points)
    print(f"log-log slope: {s:.2f} (target <= 1.2)")
    return {"series": name, "points": points, "slope": s}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--max-seconds", type=float, default=120.0,
                        help="per-survey time limit (--timeout-s)")
    args = parser.parse_args()
    results = [
        series("ROI vertices (round field, 1 km radius)",
               [1000, 2000, 4000, 8000, 16000, 32000, 49999],
               lambda n: (round_field(n), None), args.max_seconds),
        series("no-fly zones (hexagons of 1-4 m in a 2 km square, 5 m clearance)",
               [10, 100, 500, 1000, 2000, 5000],
               lambda n: (square_field(), hexagon_zones(n)), args.max_seconds),
    ]
    Path("target").mkdir(exist_ok=True)
    Path("target/bench-survey-scale.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
