"""Planning time of a fixed-wing and a VTOL survey against the multirotor
plan of the same input: bench-survey-scale.sh's 1 000-NFZ case (hexagons
of 1-4 m in a 2 km square); see bench-survey-aircraft.sh."""

import argparse
import json
import sys
import tempfile
import time
import subprocess
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_survey_scale import BINARY, LAT0, LON0, M_LAT, hexagon_zones, square_field  # noqa: E402

AIRCRAFT = {
    "multirotor": None,
    "fixed_wing": {"type": "fixed_wing"},
    "vtol": {"type": "vtol"},
}


def plan_once(work, aircraft, timeout):
    params = {"altitude_m": 120, "uavs": [{"id": "u", "start": [LON0, LAT0 - 1200 / M_LAT]}]}
    if aircraft is not None:
        params["aircraft"] = aircraft
    (work / "params.json").write_text(json.dumps(params))
    args = [str(BINARY), "survey", "--roi", str(work / "roi.geojson"),
            "--no-fly", str(work / "zones.geojson"), "--params", str(work / "params.json"),
            "--out", str(work / "out"), "--timeout-s", str(timeout)]
    began = time.perf_counter()
    run = subprocess.run(args, capture_output=True, text=True)
    took = time.perf_counter() - began
    if run.returncode != 0:
        # A plane may find no way through a dense field: timed all the same.
        return took, None, run.stderr.strip().splitlines()[-1:] or [""]
    plan = json.loads((work / "out" / "plan.json").read_text())
    return took, plan["stats"]["length_m"], plan["stats"]["flight_time_s"]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--zones", type=int, default=1000)
    parser.add_argument("--runs", type=int, default=3, help="best of this many runs")
    parser.add_argument("--max-seconds", type=float, default=120.0)
    args = parser.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        (work / "roi.geojson").write_text(json.dumps(square_field()))
        (work / "zones.geojson").write_text(json.dumps(hexagon_zones(args.zones)))
        print(f"{args.zones} NFZs, best of {args.runs}")
        print(f"{'aircraft':>11} {'seconds':>8} {'x multirotor':>13} {'length km':>10} {'time min':>9}")
        for name, aircraft in AIRCRAFT.items():
            runs = [plan_once(work, aircraft, args.max_seconds) for _ in range(args.runs)]
            took = min(r[0] for r in runs)
            ratio = took / results["multirotor"]["seconds"] if results else 1.0
            if runs[0][1] is None:
                results[name] = {"seconds": took, "ratio": ratio, "failed": runs[0][2][0]}
                print(f"{name:>11} {took:8.2f} {ratio:13.2f}  failed: {runs[0][2][0][:100]}",
                      flush=True)
                continue
            results[name] = {"seconds": took, "ratio": ratio, "length_m": runs[0][1],
                             "flight_time_s": runs[0][2]}
            print(f"{name:>11} {took:8.2f} {ratio:13.2f} {runs[0][1] / 1000:10.1f} "
                  f"{runs[0][2] / 60:9.1f}", flush=True)
    Path("target").mkdir(exist_ok=True)
    Path("target/bench-survey-aircraft.json").write_text(json.dumps(results, indent=1))
    worst = max(r["ratio"] for r in results.values())
    print(f"slowest plane: {worst:.2f}x the multirotor (target <= 3)")


if __name__ == "__main__":
    main()
