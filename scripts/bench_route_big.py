"""Benchmark `terraplan route` coarse to fine against plain A* on the
route benchmark's 4000 x 4000 costmap, and coarse to fine alone on a big
costmap (the same costmap upsampled, nearest neighbour, to --big-size).

usage: .venv/bin/python scripts/bench_route_big.py [--runs 3] [--size 4000]
           [--big-size 30000] [--max-corridor-cells N] [--work DIR] [--skip-big]

Run by scripts/bench-route-big.sh (which builds the release binary and the
validators' venv first). Downloads nothing. Environment: TERRAPLAN_BIN
(default target/release/terraplan), TERRAPLAN_SHARED_DATA (default
../shared/data), CARGO_TARGET_DIR.

1. As scripts/bench_route.py: the opengeos DTM upsampled (bilinear) to
   SIZE x SIZE, `terraplan costmap` builds its costmap, start and goal are
   the traversable cells nearest the top-left and bottom-right corners.
2. `--runs` times, interleaved, each in its own process: `terraplan route`
   with plain A* (`--coarse-to-fine-above` past the map) and with
   `--coarse-to-fine` (the costmap read by windows): the whole command's
   wall time and peak RSS (os.wait4), the search time, cost and proof from
   route.json. The two costs must agree within 1e-9 relative.
3. Unless --skip-big: the costmap's cost page upsampled to BIG x BIG
   (gdal_translate -r near, tiled 512 x 512, uncompressed; a 30000 x 30000
   map is 3.6 GB on disk in --work, default a temporary directory), and
   one coarse-to-fine route corner to corner, its wall time, peak RSS and
   search figures (with --max-corridor-cells it stops widening there and
   reports how far from optimal the route may be).

Prints a table and writes target/bench-route-big.json.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

# The validator, the shared data and the target dir as the route benchmark finds
# them (bench_route imports numpy only where it uses it, so this process's
# RSS, the floor of its children's ru_maxrss, stays small).
from bench_route import MCP, shared_data, target_dir


def timed(cmd):
    """Run `cmd`: (stdout, wall s, peak RSS MiB) of its process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = b"", b""
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    out, err = proc.stdout.read(), proc.stderr.read()
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"{' '.join(cmd)} failed:\n{err.decode(errors='replace')}")
    return out.decode(), wall, ru.ru_maxrss / 1024.0


def grid_of(tif):
    info = json.loads(subprocess.run(["gdalinfo", "-json", "-nomd", tif], check=True,
                                     capture_output=True, text=True).stdout)
    gt = info["geoTransform"]
    return (gt[0], gt[3], gt[1], -gt[5]), info["size"]


def cell_utm(grid, cell):
    r, c = cell
    x0, y0, sx, sy = grid
    return f"utm:{x0 + (c + 0.5) * sx!r},{y0 - (r + 0.5) * sy!r}"


def route(bin_, tif, frm, to, out, extra):
    stdout, wall, rss = timed([bin_, "route", tif, "--from", frm, "--to", to, "--out", out]
                              + extra)
    with open(os.path.join(out, "route.json")) as f:
        doc = json.load(f)
    return {"wall_s": wall, "peak_rss_mib": rss, "search_s": doc["search_ms"] / 1e3,
            "cost": doc["path_cost"], "expanded": doc["expanded"],
            "search": doc.get("search"), "stdout": stdout.strip()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", type=int, default=4000)
    ap.add_argument("--big-size", type=int, default=30000)
    ap.add_argument("--max-corridor-cells", type=int, default=None)
    ap.add_argument("--work", default=None)
    ap.add_argument("--skip-big", action="store_true")
    args = ap.parse_args()
    bin_ = os.environ.get("TERRAPLAN_BIN", os.path.join(target_dir(), "release", "terraplan"))
    py = sys.executable
    tmp = None
    work = args.work
    if work is None:
        tmp = tempfile.TemporaryDirectory(prefix="bench-route-big-")
        work = tmp.name
    os.makedirs(work, exist_ok=True)
    dem = os.path.join(work, f"dem{args.size}.tif")
    subprocess.run(["gdal_translate", "-q", "-r", "bilinear", "-outsize", str(args.size),
                    str(args.size), "-ot", "Float32",
                    shared_data("dems/opengeos_data__elevation_dtm.tif"), dem], check=True)
    cm_dir = os.path.join(work, f"cm{args.size}")
    subprocess.run([bin_, "costmap", dem, "--out", cm_dir], check=True,
                   stdout=subprocess.DEVNULL)
    tif = os.path.join(cm_dir, "costmap.tif")
    grid, size = grid_of(tif)
    picked = json.loads(subprocess.run([py, MCP, "pick", tif], check=True,
                                       capture_output=True, text=True).stdout)
    start, goal = picked["start"], picked["goal"]
    frm, to = cell_utm(grid, start), cell_utm(grid, goal)
    out = os.path.join(work, "route")
    plain_args = ["--coarse-to-fine-above", str(size[0] * size[1])]
    plain, c2f = [], []
    for _ in range(args.runs):
        plain.append(route(bin_, tif, frm, to, out, plain_args))
        c2f.append(route(bin_, tif, frm, to, out, ["--coarse-to-fine"]))
    med = statistics.median
    rel = abs(plain[0]["cost"] - c2f[0]["cost"]) / plain[0]["cost"]
    if rel > 1e-9:
        sys.exit(f"coarse to fine cost {c2f[0]['cost']} differs from A* {plain[0]['cost']}")
    result = {
        "size": args.size, "runs": args.runs, "start": start, "goal": goal,
        "astar": {k: med(r[k] for r in plain) for k in ("wall_s", "peak_rss_mib", "search_s")},
        "coarse_to_fine": {k: med(r[k] for r in c2f)
                           for k in ("wall_s", "peak_rss_mib", "search_s")},
        "cost_astar": plain[0]["cost"], "cost_coarse_to_fine": c2f[0]["cost"],
        "cost_rel_diff": rel, "astar_expanded": plain[0]["expanded"],
        "coarse_to_fine_search": c2f[0]["search"],
    }
    a, c = result["astar"], result["coarse_to_fine"]
    print(f"costmap {args.size}x{args.size}, route {start} -> {goal}, medians of {args.runs} "
          f"interleaved runs (whole `terraplan route` process)")
    print("| search | wall s | search s | peak RSS MiB | cost |")
    print("|---|---|---|---|---|")
    print(f"| plain A* | {a['wall_s']:.2f} | {a['search_s']:.2f} | {a['peak_rss_mib']:.0f} "
          f"| {plain[0]['cost']:.4f} |")
    print(f"| coarse to fine (windows) | {c['wall_s']:.2f} | {c['search_s']:.2f} | "
          f"{c['peak_rss_mib']:.0f} | {c2f[0]['cost']:.4f} |")
    print(f"same cost within {rel:.1e} relative; coarse to fine: {c2f[0]['stdout']}")

    if not args.skip_big:
        big = os.path.join(work, f"big{args.big_size}.tif")
        if not os.path.exists(big):
            t0 = time.perf_counter()
            subprocess.run(["gdal_translate", "-q", "-b", "1", "-r", "near", "-outsize",
                            str(args.big_size), str(args.big_size), "-co", "TILED=YES",
                            "-co", "BLOCKXSIZE=512", "-co", "BLOCKYSIZE=512",
                            "-co", "BIGTIFF=YES", tif, big], check=True)
            print(f"made {big} in {time.perf_counter() - t0:.0f} s")
        bgrid, bsize = grid_of(big)
        scale = args.big_size / args.size
        bstart = [int(start[0] * scale + scale / 2), int(start[1] * scale + scale / 2)]
        bgoal = [int(goal[0] * scale + scale / 2), int(goal[1] * scale + scale / 2)]
        extra = ["--coarse-to-fine"]
        if args.max_corridor_cells:
            extra += ["--max-corridor-cells", str(args.max_corridor_cells)]
        b = route(bin_, big, cell_utm(bgrid, bstart), cell_utm(bgrid, bgoal),
                  os.path.join(work, "route-big"), extra)
        result["big"] = {"size": args.big_size, "start": bstart, "goal": bgoal,
                         **{k: b[k] for k in ("wall_s", "peak_rss_mib", "search_s", "cost",
                                              "search")}}
        s = b["search"]
        print(f"big costmap {args.big_size}x{args.big_size} ({bsize[0] * bsize[1]} cells), "
              f"coarse to fine {bstart} -> {bgoal}: {b['wall_s']:.1f} s, peak RSS "
              f"{b['peak_rss_mib']:.0f} MiB, proven optimal {s['proven_optimal']}, "
              f"gap {100 * s['gap']:.2f} %; plain A* would hold 16 B x "
              f"{bsize[0] * bsize[1]} cells = {16 * bsize[0] * bsize[1] / 2**30:.1f} GiB")
        print(f"  {b['stdout']}")
    os.makedirs(target_dir(), exist_ok=True)
    with open(os.path.join(target_dir(), "bench-route-big.json"), "w") as f:
        json.dump(result, f, indent=1)
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
