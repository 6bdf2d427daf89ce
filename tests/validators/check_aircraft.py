"""Independent check of a plane's (fixed-wing or VTOL) survey missions.

Written against pymavlink, shapely and pyproj only (none of terraplan's code).
For every mission `<stem>.waypoints` of the output directory (with its `.plan`
for the inclusion fence) it checks:
- take-off and landing items of the type: NAV_TAKEOFF (22) with a pitch
  (param1) in (0, max climb angle] then DO_LAND_START (189) and NAV_LAND (21)
  at home for a fixed wing; NAV_VTOL_TAKEOFF (84) and NAV_VTOL_LAND (85) for a
  VTOL; no RETURN_TO_LAUNCH;
- the turn rule at every waypoint (home first, the landing point last):
  R·tan(θ/2) ≤ half of each adjacent leg (1 mm allowed, and what the
  file's 1e-8° positions can change in θ and the legs);
- the rounded path (tangent arcs of radius R at every waypoint, what an
  autopilot cutting corners flies) keeps the clearance from the NFZs and
  stays that far inside the .plan's inclusion fence (1 cm allowed); a disc
  of the clearance round home is left out (take-off and landing);
- climbs and descents between waypoints within the climb angle (the
  take-off's climb is its pitch; a VTOL's take-off and landing are vertical);
- the camera only on straight lanes: every DO_SET_CAM_TRIGG_DIST on/off pair
  brackets one straight line (one leg, or collinear legs over a DEM) inside the ROI less the NFZs (1 m allowed), entered
  and left straight (the legs before and after run along it; how many are at
  least the lead-in long is reported);
- photo footprints (a photo every trigger distance along each lane, from its
  start; footprint from the pinhole camera at the altitude) cover at least
  --min-coverage of the ROI less the NFZs;
- with a plan.json in OUT_DIR: its coverage_ratio is that of the lanes flown
  (each lane's strip footprint_side_m wide with flat ends, united, within
  the ROI less the NFZs) within COVERAGE_TOL, and its lane_count the lanes
  flown: not the lanes planned before the plane pulled some back.

A corridor survey is checked with --corridor-width W and the centre line
(a GeoJSON LineString) in place of the ROI: the area is then the line's
flat-capped buffer by W / 2 (shapely's own).

usage: check_aircraft.py OUT_DIR ROI.geojson [NFZ.geojson ...] --type fixed_wing|vtol
       --radius R --climb DEG --clearance C --lead-in L --altitude A
       [--sensor W H F] [--min-coverage 0.995] [--corridor-width W]
Prints a JSON summary; exits 1 with a message on the first failed check.
"""
import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import shapely
from pymavlink import mavwp
from pyproj import Transformer
from shapely import force_2d
from shapely.affinity import rotate, translate
from shapely.geometry import LineString, Point, Polygon, box, shape
from shapely.ops import unary_union


from photo_rule import photo_count  # noqa: E402

RULE_TOL_M = 1e-3
# Positions in a .waypoints file have 8 decimals of a degree: up to ~1.2 mm
# off, which turns a short leg a little.
QUANT_M = 1.2e-3
CLEAR_TOL_M = 0.01
# plan.json's coverage ratio against the flown lanes' strips (the files'
# 1e-8° positions move a strip by a millimetre or so).
COVERAGE_TOL = 1e-3
ANGLE_TOL = 1e-6
NAV_WAYPOINT, NAV_LAND, NAV_TAKEOFF, NAV_RTL = 16, 21, 22, 20
VTOL_TAKEOFF, VTOL_LAND, LAND_START, CAM_DIST = 84, 85, 189, 206


def fail(msg):
    print(msg, file=sys.stderr)
    sys.exit(1)


def utm_epsg(lon, lat):
    return (32600 if lat >= 0 else 32700) + int((lon + 180) // 6) + 1


def read_area(paths):
    geoms = []
    for path in paths:
        doc = json.loads(Path(path).read_text())
        feats = doc["features"] if doc.get("type") == "FeatureCollection" else [doc]
        for f in feats:
            g = force_2d(shape(f["geometry"] if f.get("type") == "Feature" else f))
            geoms.append(g if g.is_valid else g.buffer(0))
    return unary_union(geoms) if geoms else None


def turn(a, b, c):
    u = (b[0] - a[0], b[1] - a[1])
    v = (c[0] - b[0], c[1] - b[1])
    return abs(math.atan2(u[0] * v[1] - u[1] * v[0], u[0] * v[0] + u[1] * v[1]))


def dist(a, b):
    return math.hypot(b[0] - a[0], b[1] - a[1])


def rounded(pts, r):
    """The path through pts with a tangent arc of radius r at every corner."""
    out = [pts[0]]
    for i in range(1, len(pts) - 1):
        a, b, c = pts[i - 1], pts[i], pts[i + 1]
        th = turn(a, b, c)
        lab, lbc = dist(a, b), dist(b, c)
        if th < 1e-9 or lab < 1e-12 or lbc < 1e-12:
            out.append(b)
            continue
        t = r * math.tan(th / 2)
        u = ((b[0] - a[0]) / lab, (b[1] - a[1]) / lab)
        v = ((c[0] - b[0]) / lbc, (c[1] - b[1]) / lbc)
        p = (b[0] - u[0] * t, b[1] - u[1] * t)
        left = u[0] * v[1] - u[1] * v[0] > 0
        n = (-u[1], u[0]) if left else (u[1], -u[0])
        centre = (p[0] + n[0] * r, p[1] + n[1] * r)
        start = math.atan2(p[1] - centre[1], p[0] - centre[0])
        sweep = th if left else -th
        k = max(1, math.ceil(th / math.radians(2)))
        for j in range(k + 1):
            ang = start + sweep * j / k
            out.append((centre[0] + r * math.cos(ang), centre[1] + r * math.sin(ang)))
    out.append(pts[-1])
    return out


def fence_polygon(plan_path, to_utm):
    plan = json.loads(Path(plan_path).read_text())
    for p in plan["geoFence"]["polygons"]:
        if p["inclusion"]:
            return Polygon([to_utm(lon, lat) for lat, lon in p["polygon"]])
    fail(f"{plan_path}: no inclusion fence")


def check_mission(wp_path, args, roi, free, nfz, to_utm):
    loader = mavwp.MAVWPLoader()
    loader.load(str(wp_path))
    items = [loader.wp(i) for i in range(loader.count())]
    home = items[0]
    cmds = [w.command for w in items[1:]]
    stem = wp_path.name[: -len(".waypoints")]
    if NAV_RTL in cmds:
        fail(f"{stem}: a plane's mission ends with its own landing, not RTL")
    if args.type == "fixed_wing":
        if cmds[0] != NAV_TAKEOFF:
            fail(f"{stem}: the first item is {cmds[0]}, not NAV_TAKEOFF")
        pitch = items[1].param1
        if not (0 < pitch <= args.climb + ANGLE_TOL):
            fail(f"{stem}: take-off pitch {pitch} outside (0, {args.climb}]")
        if cmds[-1] != NAV_LAND or cmds[-3] != LAND_START:
            fail(f"{stem}: not DO_LAND_START, approach waypoint, NAV_LAND at the end: {cmds[-4:]}")
    else:
        if cmds[0] != VTOL_TAKEOFF or cmds[-1] != VTOL_LAND:
            fail(f"{stem}: a VTOL takes off with 84 and lands with 85, found {cmds[0]} … {cmds[-1]}")
    last = items[-1]
    if dist(to_utm(last.y, last.x), to_utm(home.y, home.x)) > 0.05:
        fail(f"{stem}: the landing is not at home")

    # Positions flown, in order: home, the take-off's point, waypoints, landing.
    track = [(to_utm(home.y, home.x), 0.0, "home")]
    camera_on_at = None
    lanes = []
    for w in items[1:]:
        if w.command in (NAV_TAKEOFF, VTOL_TAKEOFF):
            track.append((to_utm(w.y, w.x), w.z, "takeoff"))
        elif w.command in (NAV_WAYPOINT, NAV_LAND, VTOL_LAND):
            track.append((to_utm(w.y, w.x), w.z, w.command))
        elif w.command == CAM_DIST:
            if w.param1 > 0:
                if camera_on_at is not None:
                    fail(f"{stem}: camera switched on twice")
                camera_on_at = len(track) - 1
                trigger = w.param1
            else:
                if camera_on_at is None:
                    fail(f"{stem}: camera switched off while off")
                lanes.append((camera_on_at, len(track) - 1, trigger))
                camera_on_at = None
    if camera_on_at is not None:
        fail(f"{stem}: the camera is left on")

    # Horizontal path: home, then every waypoint (the take-off point is home).
    pts = [track[0][0]] + [p for p, _, kind in track[2:]]
    worst_rule = -math.inf
    for i in range(1, len(pts) - 1):
        th = turn(pts[i - 1], pts[i], pts[i + 1])
        l1, l2 = dist(pts[i - 1], pts[i]), dist(pts[i], pts[i + 1])
        half = min(l1, l2) / 2
        excess = args.radius * math.tan(th / 2) - half
        worst_rule = max(worst_rule, excess)
        d_theta = 2 * QUANT_M / max(l1, 1e-9) + 2 * QUANT_M / max(l2, 1e-9)
        slack = RULE_TOL_M + QUANT_M + args.radius * d_theta / (2 * math.cos(th / 2) ** 2)
        if excess > slack:
            fail(f"{stem}: waypoint {i}: R·tan(θ/2) = {args.radius * math.tan(th / 2):.3f} m "
                 f"over half a leg ({half:.3f} m)")

    path = LineString(rounded(pts, args.radius))
    home_disc = Point(pts[0]).buffer(args.clearance + 1.0)
    away = path.difference(home_disc)
    min_nfz = math.inf
    if nfz is not None and not away.is_empty:
        min_nfz = away.distance(nfz)
        if min_nfz < args.clearance - CLEAR_TOL_M:
            fail(f"{stem}: the rounded path comes within {min_nfz:.3f} m of an NFZ")
    fence = fence_polygon(wp_path.with_suffix(".plan"), to_utm)
    if not fence.contains(path):
        fail(f"{stem}: the rounded path leaves the inclusion fence")
    min_fence = away.distance(fence.exterior) if not away.is_empty else math.inf
    if min_fence < args.clearance - CLEAR_TOL_M:
        fail(f"{stem}: the rounded path comes within {min_fence:.3f} m of the fence")

    # Climb angles along the track (home on the ground).
    tan_max = math.tan(math.radians(args.climb))
    steepest = 0.0
    for k in range(1, len(track)):
        (a, za, _), (b, zb, kind) = track[k - 1], track[k]
        if kind == "takeoff" or kind == VTOL_LAND:
            continue  # vertical (VTOL) or at the take-off pitch (checked)
        h = dist(a, b)
        if abs(zb - za) < 1e-6:
            continue
        if h < 1e-6:
            fail(f"{stem}: a vertical step of {zb - za:.2f} m at item {k}")
        slope = abs(zb - za) / h
        steepest = max(steepest, math.degrees(math.atan(slope)))
        # The file's positions (1e-8°) and altitudes (1e-6 m) are rounded.
        if slope > tan_max * (1 + 2 * QUANT_M / h) + 2e-6 / h:
            fail(f"{stem}: a slope of {math.degrees(math.atan(slope)):.2f}° at item {k}")

    # Lanes: one straight leg each, entered and left straight, in free space.
    footprints = []
    segments = []
    runs = []
    tpts = [p for p, _, _ in track]
    for on, off, trigger in lanes:
        a, b = tpts[on], tpts[off]
        # Over a DEM a lane is split into legs: all on one straight line.
        for k in range(on + 1, off):
            if LineString([a, b]).distance(Point(tpts[k])) > 0.01 or \
                    turn(tpts[k - 1], tpts[k], tpts[k + 1]) > 1e-3:
                fail(f"{stem}: the camera is on through a turn at item {k}")
        lane = LineString([a, b])
        if lane.length < 1e-6:
            fail(f"{stem}: a lane of no length")
        if free.buffer(1.0).intersection(lane).length < lane.length - 1e-3:
            fail(f"{stem}: a lane leaves the ROI less the NFZs")
        before, after = tpts[on - 1], tpts[off + 1]
        for bent, run, what in ((turn(before, a, b), dist(before, a), "lead-in"),
                                (turn(a, b, after), dist(b, after), "overshoot")):
            # The file's 1e-8° positions turn a short run by up to this.
            if bent > 1e-3 + 2 * QUANT_M / max(run, 1e-9):
                fail(f"{stem}: lane from item {on} is not entered and left straight ({what})")
            runs.append(run)
        segments.append(lane)
        ux, uy = (b[0] - a[0]) / lane.length, (b[1] - a[1]) / lane.length
        angle = math.degrees(math.atan2(uy, ux))
        n = photo_count(lane.length, trigger)
        for k in range(n):
            cx, cy = a[0] + ux * trigger * k, a[1] + uy * trigger * k
            fp = box(-args.front / 2, -args.side / 2, args.front / 2, args.side / 2)
            footprints.append(translate(rotate(fp, angle, origin=(0, 0)), cx, cy))
    return {
        "waypoints": len(pts),
        "lanes": lanes,
        "footprints": footprints,
        "segments": segments,
        "worst_rule_excess_m": worst_rule,
        "min_nfz_distance_m": min_nfz if math.isfinite(min_nfz) else None,
        "min_fence_distance_m": min_fence if math.isfinite(min_fence) else None,
        "steepest_deg": steepest,
        "shortest_run_m": min(runs) if runs else None,
        "full_runs": sum(r >= args.lead_in - 1e-3 for r in runs),
        "runs": len(runs),
    }


def check_plan_coverage(stats, segments, free, summary):
    """plan.json's coverage ratio and lane count against the lanes flown."""
    half = stats["footprint_side_m"] / 2
    strips = unary_union([s.buffer(half, cap_style="flat") for s in segments])
    swept = strips.intersection(free).area / free.area
    summary["swath_coverage"] = swept
    summary["plan_coverage_ratio"] = stats["coverage_ratio"]
    if abs(swept - stats["coverage_ratio"]) > COVERAGE_TOL:
        fail(f"plan.json's coverage_ratio {stats['coverage_ratio']:.5f} is not that of the lanes "
             f"flown ({swept:.5f})")
    if stats["lane_count"] != len(segments):
        fail(f"plan.json's lane_count {stats['lane_count']} is not the {len(segments)} lanes flown")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("roi")
    ap.add_argument("nfz", nargs="*")
    ap.add_argument("--type", required=True, choices=["fixed_wing", "vtol"])
    ap.add_argument("--radius", type=float, required=True)
    ap.add_argument("--climb", type=float, required=True)
    ap.add_argument("--clearance", type=float, required=True)
    ap.add_argument("--lead-in", type=float, required=True)
    ap.add_argument("--altitude", type=float, required=True)
    ap.add_argument("--sensor", type=float, nargs=3, default=[13.2, 8.8, 8.8])
    ap.add_argument("--min-coverage", type=float, default=0.995)
    ap.add_argument("--corridor-width", type=float)
    args = ap.parse_args()
    # Landscape: the sensor's width across the track.
    sw, sh, f = args.sensor
    args.side = args.altitude * sw / f
    args.front = args.altitude * sh / f

    if args.corridor_width is not None:
        doc = json.loads(Path(args.roi).read_text())
        if doc.get("type") == "FeatureCollection":
            doc = doc["features"][0]
        roi_ll = force_2d(shape(doc["geometry"] if doc.get("type") == "Feature" else doc))
    else:
        roi_ll = read_area([args.roi])
    c = roi_ll.representative_point()
    tr = Transformer.from_crs(4326, utm_epsg(c.x, c.y), always_xy=True)

    def to_utm(lon, lat):
        return tr.transform(lon, lat)

    def project(g):
        return shapely.transform(g, lambda c: np.column_stack(tr.transform(c[:, 0], c[:, 1])))

    roi = project(roi_ll)
    if args.corridor_width is not None:
        roi = roi.buffer(args.corridor_width / 2, cap_style="flat")
    nfz_ll = read_area(args.nfz)
    nfz = project(nfz_ll) if nfz_ll is not None else None
    free = roi.difference(nfz) if nfz is not None else roi

    out = Path(args.out)
    missions = sorted(p for p in out.glob("*.waypoints")
                      if not p.name.endswith((".fence.waypoints", ".rally.waypoints")))
    if not missions:
        fail(f"no missions in {out}")
    summary = {"missions": {}, "lanes": 0}
    footprints = []
    segments = []
    for wp in missions:
        r = check_mission(wp, args, roi, free, nfz, to_utm)
        footprints.extend(r.pop("footprints"))
        segments.extend(r.pop("segments"))
        summary["lanes"] += len(r.pop("lanes"))
        summary["missions"][wp.name] = r
    covered = unary_union(footprints).intersection(free).area / free.area
    summary["footprint_coverage"] = covered
    if covered < args.min_coverage:
        fail(f"photo footprints cover {covered:.4%} of the free area, under {args.min_coverage:.2%}")
    plan_path = out / "plan.json"
    if plan_path.exists():
        check_plan_coverage(json.loads(plan_path.read_text())["stats"], segments, free, summary)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
