"""Benchmark `terraplan route` next to scikit-image's MCP_Geometric and
pyastar2d on the same cost array, and D* Lite replanning after blocking
20 m of the route.

usage: .venv/bin/python scripts/bench_route.py [--runs 3] [--size 4000]
       .venv/bin/python scripts/bench_route.py pyastar2d COSTMAP.tif ROW,COL ROW,COL

Run by scripts/bench-route.sh (which builds the release binary and the
validators' venv first). Downloads nothing. Environment: TERRAPLAN_BIN
(default target/release/terraplan), TERRAPLAN_SHARED_DATA (default
../shared/data), CARGO_TARGET_DIR.

1. The opengeos DTM is upsampled (bilinear) to SIZE x SIZE and
   `terraplan costmap` builds its costmap (U-Go defaults).
2. Start and goal: the traversable cells nearest the top-left and
   bottom-right corners in the largest traversable region.
3. `--runs` times, interleaved: `terraplan route COSTMAP --from --to`
   (the A* time it reports, and the whole command's wall time and peak
   RSS), MCP_Geometric (fully connected, geometric: the same arc rule)
   constructing and searching from start to goal, and pyastar2d's
   `astar_path` (the `pyastar2d` subcommand), each in its own process.
4. `terraplan route --block --replan-from` with a polygon over 20 m of the
   route around its middle (4 m wide), seen by the robot 20 m before it:
   D* Lite's first search, its replan from the robot's position after the
   block, and A* from scratch from there on the changed map, all in one
   process (next to that process's own A* route search).

pyastar2d (C++ A* on a numpy grid, 8-connected with `allow_diagonal`) has
its own cost model: a step into a cell costs that cell's weight, whatever
its length (a diagonal costs what an orthogonal step does), and it may
step diagonally between two obstacle cells. It is given the costmap's
costs as weights (they are >= 1, as its Chebyshev heuristic needs;
obstacles +inf), so it finds the cheapest path under its model; that path
is then costed under terraplan's `integrated` rule (step length x the mean
of the two costs, metres from the cell size) and checked for corner cuts,
so both paths are compared on one scale. terraplan's A* path is optimal
under that rule, so pyastar2d's can only cost as much or more (less only
by cutting corners, which are counted).

Targets (issue 7, 21): A* >= 5x faster than MCP at identical cost (MCP may
be cheaper where it cuts corners between obstacle cells) and >= 2x faster
than pyastar2d at equal or lower cost; D* Lite's first search <= 1.5x A*'s
time; the D* Lite replan <= 10 % of a search from scratch; search memory
<= 16 bytes per cell. Prints a table and writes target/bench-route.json.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MCP = os.path.join(ROOT, "tests", "validators", "mcp_route.py")


def pyastar2d_route(tif, start, goal):
    """pyastar2d's path between two cells of a costmap, timed, and costed
    under terraplan's integrated rule (see the module docs)."""
    import numpy as np
    import pyastar2d
    sys.path.insert(0, os.path.dirname(MCP))
    from mcp_route import read_costmap

    cost, (dx, dy), _ = read_costmap(tif)
    weights = cost.astype(np.float32)  # obstacles are already +inf
    t = time.perf_counter()
    path = pyastar2d.astar_path(weights, tuple(start), tuple(goal), allow_diagonal=True)
    seconds = time.perf_counter() - t
    if path is None:
        return {"seconds": seconds, "found": False}
    r, c = path[:, 0].astype(np.int64), path[:, 1].astype(np.int64)
    dr, dc = np.diff(r), np.diff(c)
    length = np.hypot(dc * dx, dr * dy)
    here, there = cost[r[:-1], c[:-1]], cost[r[1:], c[1:]]
    diagonal = (dr != 0) & (dc != 0)
    beside = (cost[r[:-1][diagonal] + dr[diagonal], c[:-1][diagonal]],
              cost[r[:-1][diagonal], c[:-1][diagonal] + dc[diagonal]])
    cuts = int(np.sum(~(np.isfinite(beside[0]) & np.isfinite(beside[1]))))
    return {
        "seconds": seconds, "found": True, "cells": int(len(path)),
        "cost_integrated": float(np.sum(length * 0.5 * (here + there))),
        "cost_own_model": float(np.sum(weights[r[1:], c[1:]], dtype=np.float64)),
        "length_m": float(np.sum(length)), "diagonal_steps": int(np.sum(diagonal)),
        "corner_cuts": cuts,
    }


def shared_data(rel):
    base = os.environ.get("TERRAPLAN_SHARED_DATA", os.path.join(ROOT, "..", "shared", "data"))
    p = os.path.normpath(os.path.join(base, rel))
    if not os.path.exists(p):
        sys.exit(f"shared test data {p} is missing")
    return p


def target_dir():
    return os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))


def run(cmd, capture=True):
    """Run `cmd`: (stdout, wall s, peak RSS MiB)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = proc.communicate()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{err.decode(errors='replace')}")
    # communicate() reaped the child; its rusage is in RUSAGE_CHILDREN,
    # which keeps the maximum over all children: measure separately below.
    return out.decode(), wall


def peak_rss_mib(cmd):
    """Peak RSS of one run of `cmd` (os.wait4's ru_maxrss, KiB on Linux)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, ru = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{' '.join(cmd)} failed")
    return ru.ru_maxrss / 1024.0


def cell_utm(info, cell):
    r, c = cell
    x0, y0, sx, sy = info
    return f"utm:{x0 + (c + 0.5) * sx!r},{y0 - (r + 0.5) * sy!r}"


def main():
    if sys.argv[1:2] == ["pyastar2d"]:
        cell = lambda s: [int(v) for v in s.split(",")]
        print(json.dumps(pyastar2d_route(sys.argv[2], cell(sys.argv[3]), cell(sys.argv[4]))))
        return
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", type=int, default=4000)
    args = ap.parse_args()
    bin_ = os.environ.get("TERRAPLAN_BIN", os.path.join(target_dir(), "release", "terraplan"))
    py = sys.executable
    with tempfile.TemporaryDirectory(prefix="bench-route-") as work:
        dem = os.path.join(work, "dem.tif")
        subprocess.run(["gdal_translate", "-q", "-r", "bilinear", "-outsize", str(args.size),
                        str(args.size), "-ot", "Float32",
                        shared_data("dems/opengeos_data__elevation_dtm.tif"), dem], check=True)
        cm_dir = os.path.join(work, "cm")
        _, costmap_s = run([bin_, "costmap", dem, "--out", cm_dir])
        tif = os.path.join(cm_dir, "costmap.tif")
        info = json.loads(subprocess.run(["gdalinfo", "-json", "-nomd", tif], check=True,
                                         capture_output=True, text=True).stdout)
        gt = info["geoTransform"]
        grid = (gt[0], gt[3], gt[1], -gt[5])
        cells = info["size"][0] * info["size"][1]
        picked = json.loads(run([py, MCP, "pick", tif])[0])
        start, goal = picked["start"], picked["goal"]
        frm, to = cell_utm(grid, start), cell_utm(grid, goal)
        route_dir = os.path.join(work, "route")
        route_cmd = [bin_, "route", tif, "--from", frm, "--to", to, "--out", route_dir]
        cell_arg = lambda c: f"{c[0]},{c[1]}"
        mcp_cmd = [py, MCP, "cost", tif, cell_arg(start), cell_arg(goal)]
        pya_cmd = [py, os.path.abspath(__file__), "pyastar2d", tif, cell_arg(start),
                   cell_arg(goal)]

        ours, ours_wall, theirs, theirs_wall, pya, pya_wall = [], [], [], [], [], []
        for _ in range(args.runs):
            _, wall = run(route_cmd)
            with open(os.path.join(route_dir, "route.json")) as f:
                route = json.load(f)
            ours.append(route["search_ms"] / 1e3)
            ours_wall.append(wall)
            out, wall = run(mcp_cmd)
            m = json.loads(out)
            theirs.append(m["seconds"])
            theirs_wall.append(wall)
            out, wall = run(pya_cmd)
            p = json.loads(out)
            if not p["found"]:
                sys.exit("pyastar2d found no path")
            pya.append(p["seconds"])
            pya_wall.append(wall)
        ours_rss = peak_rss_mib(route_cmd)
        mcp_rss = peak_rss_mib(mcp_cmd)
        pya_rss = peak_rss_mib(pya_cmd)

        block = os.path.join(work, "block.geojson")
        blocked = json.loads(run([py, MCP, "block", os.path.join(route_dir, "route.json"),
                                  block, "20", "2"])[0])
        robot = "utm:{!r},{!r}".format(*blocked["robot_utm"])
        replans, same_process_astar = [], []
        for _ in range(args.runs):
            run(route_cmd + ["--block", block, "--replan-from", robot])
            with open(os.path.join(route_dir, "replanned", "timing.json")) as f:
                replans.append(json.load(f))
            with open(os.path.join(route_dir, "route.json")) as f:
                same_process_astar.append(json.load(f)["search_ms"])

    med = statistics.median
    a_star, mcp = med(ours), med(theirs)
    rel = (route["path_cost"] - m["cost"]) / m["cost"]
    d_replan = med(r["dstar_lite"]["replan_ms"] for r in replans)
    d_initial = med(r["dstar_lite"]["initial_ms"] for r in replans)
    scratch = med(r["astar_from_scratch"]["ms"] for r in replans)
    r0 = replans[0]
    # D* Lite's first search against the A* search of the same process.
    first_ratio = med(r["dstar_lite"]["initial_ms"] / a for r, a in zip(replans, same_process_astar))
    pya_s = med(pya)
    pya_rel = (p["cost_integrated"] - route["path_cost"]) / route["path_cost"]
    result = {
        "size": args.size, "cells": cells, "runs": args.runs, "costmap_s": costmap_s,
        "start": start, "goal": goal,
        "astar_s": a_star, "mcp_s": mcp, "speedup": mcp / a_star,
        "pyastar2d_s": pya_s, "speedup_vs_pyastar2d": pya_s / a_star,
        "pyastar2d": p, "pyastar2d_cost_rel_diff": pya_rel,
        "pyastar2d_process_wall_s": med(pya_wall), "pyastar2d_peak_rss_mib": pya_rss,
        "route_command_wall_s": med(ours_wall), "mcp_process_wall_s": med(theirs_wall),
        "route_cost": route["path_cost"], "mcp_cost": m["cost"], "cost_rel_diff": rel,
        "expanded": route["expanded"],
        "route_peak_rss_mib": ours_rss, "mcp_peak_rss_mib": mcp_rss,
        "route_peak_bytes_per_cell": ours_rss * 1024 * 1024 / cells,
        "block": blocked, "blocked_cells": r0["blocked_cells"],
        "dstar_initial_ms": d_initial, "dstar_replan_ms": d_replan,
        "dstar_initial_vs_astar": first_ratio,
        "astar_same_process_ms": med(same_process_astar),
        "astar_scratch_ms": scratch,
        "replan_vs_astar_scratch": d_replan / scratch,
        "replan_vs_dstar_initial": d_replan / d_initial,
        "replan_expanded": r0["dstar_lite"]["replan_expanded"],
        "dstar_initial_expanded": r0["dstar_lite"]["initial_expanded"],
        "astar_scratch_expanded": r0["astar_from_scratch"]["expanded"],
        "replan_cost_equals_scratch": abs(r0["dstar_lite"]["replan_cost"]
                                          - r0["astar_from_scratch"]["cost"])
        <= 1e-9 * r0["astar_from_scratch"]["cost"],
    }
    print(f"costmap {args.size}x{args.size} ({cells} cells) built in {costmap_s:.2f} s; "
          f"route corner to corner {start} -> {goal}, medians of {args.runs}")
    print(f"| search | seconds | cost | expanded |")
    print(f"|---|---|---|---|")
    print(f"| terraplan A* | {a_star:.3f} | {route['path_cost']:.2f} | {route['expanded']} |")
    print(f"| scikit-image MCP_Geometric | {mcp:.3f} | {m['cost']:.2f} | all |")
    print(f"| pyastar2d | {pya_s:.3f} | {p['cost_integrated']:.2f} | - |")
    print(f"speed-up {mcp / a_star:.1f}x over MCP (target >= 5x); cost difference {rel:+.2e} "
          f"relative (MCP cuts corners between obstacle cells, so it may be lower)")
    print(f"speed-up {pya_s / a_star:.1f}x over pyastar2d (target >= 2x); its path costs "
          f"{100 * pya_rel:+.2f} % under terraplan's integrated rule ({p['cells']} cells, "
          f"{p['diagonal_steps']} diagonal steps, {p['corner_cuts']} corner cuts, "
          f"{p['length_m']:.1f} m; {p['cost_own_model']:.1f} under its own model: unit steps, "
          f"the entered cell's weight); process {med(pya_wall):.2f} s, {pya_rss:.0f} MiB")
    print(f"whole `terraplan route` command {med(ours_wall):.2f} s, peak RSS {ours_rss:.0f} MiB "
          f"({result['route_peak_bytes_per_cell']:.1f} B/cell, reading the file included); "
          f"MCP process {med(theirs_wall):.2f} s, {mcp_rss:.0f} MiB")
    print(f"blocked {blocked['stretch_m']:.0f} m of the route ({r0['blocked_cells']} cells), "
          f"seen 20 m before it: "
          f"D* Lite replan {d_replan:.1f} ms ({r0['dstar_lite']['replan_expanded']} expanded) = "
          f"{100 * d_replan / scratch:.1f} % of A* from scratch ({scratch:.1f} ms, "
          f"{r0['astar_from_scratch']['expanded']} expanded), {100 * d_replan / d_initial:.1f} % "
          f"of D* Lite's first search ({d_initial:.1f} ms); same cost: "
          f"{result['replan_cost_equals_scratch']}")
    print(f"D* Lite's first search {d_initial:.1f} ms = {first_ratio:.2f}x the A* route search of "
          f"the same process ({med(same_process_astar):.1f} ms; target <= 1.5x), "
          f"{r0['dstar_lite']['initial_expanded']} expanded")
    os.makedirs(target_dir(), exist_ok=True)
    with open(os.path.join(target_dir(), "bench-route.json"), "w") as f:
        json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
