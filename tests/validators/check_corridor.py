"""Independent check of a terraplan corridor survey output directory.

Written against pymavlink, shapely and pyproj only (none of terraplan's
code). The corridor is made here from the centre line: shapely's
`buffer(width / 2, cap_style="flat")` (round joins) in the UTM metres of
plan.json. For every sortie's `.waypoints` (read by pymavlink):

- away from home every flown segment keeps nfz_clearance_m from the no-fly
  zones and stays that far inside the .plan's inclusion fence
  (clearance.py);
- no two consecutive waypoints at one place (a lane going on round a bend
  is not written twice);
- the survey lanes (waypoints flown with the camera triggering, from a
  DO_SET_CAM_TRIGG_DIST > 0 to the next = 0) stay in the corridor and run
  along the centre line: each lane segment keeps its distance from the
  line within 0.3 m plus 2 % (the chords of arcs round bends);
- the photos: one where triggering starts and one every trigger distance
  after it along the lane (ArduPilot's and PX4's distance triggering), each
  a footprint_side_m × footprint_front_m rectangle across and along the
  lane; their count equals plan.json's and their union covers at least
  MIN_COVERAGE of the corridor minus the no-fly zones;
- the lanes' swaths (flat-ended strips footprint_side_m wide, the planner's
  own measure) cover the same share plan.json reports, within 0.002;
- plan.json's area is the corridor's within 0.5 % (the planner's arcs are
  drawn with other steps than shapely's).

usage: check_corridor.py OUT_DIR LINE.geojson WIDTH_M [NFZ.geojson ...]
Prints a JSON summary; exits 1 with a message on the first failed check.
"""
import json
import math
import sys
from pathlib import Path

from pymavlink import mavutil, mavwp
from pyproj import Transformer
import shapely
from shapely.geometry import LineString, Point, Polygon, shape
from shapely.ops import unary_union

sys.path.insert(0, str(Path(__file__).parent))
from clearance import check as clearance_check, inclusion_rings, read_zones  # noqa: E402

from photo_rule import PHOTO_END_TOLERANCE_M  # noqa: E402

CMD_WAYPOINT = mavutil.mavlink.MAV_CMD_NAV_WAYPOINT
CMD_TRIGG = mavutil.mavlink.MAV_CMD_DO_SET_CAM_TRIGG_DIST
MIN_COVERAGE = 0.995
# 5 cm for the lon/lat round trip of points on the corridor's edge.
GEOM_TOL_M = 0.05
# The planner draws lanes within 0.25 m of their offset curve.
PARALLEL_TOL_M = 0.3


def fail(msg):
    print(f"check_corridor: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def read_line(path):
    doc = json.loads(Path(path).read_text())
    if doc.get("type") == "FeatureCollection":
        doc = doc["features"][0]
    if doc.get("type") == "Feature":
        doc = doc["geometry"]
    if doc["type"] != "LineString":
        fail(f"{path}: not a LineString")
    return LineString([c[:2] for c in doc["coordinates"]])


def lane_runs(items):
    """Lanes as lists of waypoints: triggering on at the first, off after
    the last."""
    runs, current, last_wp = [], None, None
    for it in items[1:]:
        if it.command == CMD_TRIGG:
            if it.param1 > 0:
                current = [last_wp]
                trigger = it.param1
            elif current is not None:
                runs.append((current, trigger))
                current = None
        elif it.command == CMD_WAYPOINT:
            last_wp = it
            if current is not None:
                current.append(it)
    return runs


def photos(points, trigger_m, side_m, front_m):
    """Footprints of the photos along one lane polyline (metres)."""
    out = []
    next_at = 0.0
    run = 0.0
    last = len(points) - 2
    for k, (a, b) in enumerate(zip(points, points[1:])):
        seg = math.dist(a, b)
        if seg == 0:
            continue
        ux, uy = (b[0] - a[0]) / seg, (b[1] - a[1]) / seg
        # The plan's rule (planner-core coverage::photo_count): the far
        # photo counts when the lane reaches within 1 cm of it (files round
        # positions to about a millimetre).
        tol = PHOTO_END_TOLERANCE_M if k == last else 1e-9
        while next_at <= run + seg + tol:
            t = next_at - run
            cx, cy = a[0] + ux * t, a[1] + uy * t
            hx, hy = ux * front_m / 2, uy * front_m / 2
            sx, sy = -uy * side_m / 2, ux * side_m / 2
            out.append(Polygon([(cx - hx - sx, cy - hy - sy), (cx + hx - sx, cy + hy - sy),
                                (cx + hx + sx, cy + hy + sy), (cx - hx + sx, cy - hy + sy)]))
            next_at += trigger_m
        run += seg
    return out


def main():
    out = Path(sys.argv[1])
    line_ll = read_line(sys.argv[2])
    width = float(sys.argv[3])
    zones = read_zones(sys.argv[4:])
    plan = json.loads((out / "plan.json").read_text())
    stats = plan["stats"]
    fwd = Transformer.from_crs("EPSG:4326", f"EPSG:{plan['utm_epsg']}", always_xy=True).transform

    def project(g):
        return shapely.transform(g, fwd, interleaved=False)

    centre = project(line_ll)
    corridor = centre.buffer(width / 2, cap_style="flat")
    nfz = project(zones) if zones is not None and not zones.is_empty else None
    free = corridor.difference(nfz) if nfz is not None else corridor
    grown = corridor.buffer(GEOM_TOL_M)
    if abs(corridor.area - stats["area_m2"]) > 0.005 * corridor.area:
        fail(f"corridor area {corridor.area:.1f} m² here, {stats['area_m2']:.1f} m² in plan.json")

    clearance = stats.get("nfz_clearance_m", 0.0)
    side, front = stats["footprint_side_m"], stats["footprint_front_m"]
    summary = {"uavs": {}, "corridor_area_m2": corridor.area, "free_area_m2": free.area}
    lane_lines, shots = [], []
    for uav in plan["uavs"]:
        for sortie in uav["sorties"]:
            uid = sortie["file_stem"]
            wp_path = out / f"{uid}.waypoints"
            loader = mavwp.MAVWPLoader()
            n = loader.load(str(wp_path))
            items = [loader.wp(i) for i in range(n)]
            home = items[0]
            wps = [it for it in items[1:] if it.command == CMD_WAYPOINT]
            pts = [fwd(home.y, home.x)] + [fwd(w.y, w.x) for w in wps] + [fwd(home.y, home.x)]
            for w, v in zip(wps, wps[1:]):
                a, b = fwd(w.y, w.x), fwd(v.y, v.x)
                if math.dist(a, b) < 1e-3 and abs(w.z - v.z) < 1e-3:
                    fail(f"{wp_path}: two consecutive waypoints at {a}, {w.z} m (a lane going on "
                         f"round a bend is written once)")
            try:
                d_nfz, _ = clearance_check(clearance, pts, nfz,
                                           inclusion_rings(out / f"{uid}.plan", fwd), wp_path)
            except ValueError as e:
                fail(str(e))
            if d_nfz is not None:
                summary["min_nfz_distance_m"] = min(summary.get("min_nfz_distance_m", d_nfz), d_nfz)
            runs = lane_runs(items)
            for run, trigger in runs:
                lane = [fwd(w.y, w.x) for w in run]
                if len(lane) < 2:
                    fail(f"{wp_path}: a lane of one waypoint (the camera on and off at one place)")
                line = LineString(lane)
                if not grown.contains(line):
                    fail(f"{wp_path}: survey lane {line.wkt} leaves the corridor")
                for a, b in zip(lane, lane[1:]):
                    check_parallel(a, b, centre, wp_path)
                lane_lines.append(line)
                shots.extend(photos(lane, trigger, side, front))
            summary["uavs"][uid] = {"items": n, "waypoints": len(wps), "lanes": len(runs)}

    if len(shots) != stats["photos"]:
        fail(f"{len(shots)} photos along the lanes, plan.json says {stats['photos']}")
    covered = unary_union(shots).intersection(free).area / free.area
    summary["photo_coverage"] = covered
    summary["photos"] = len(shots)
    if covered < MIN_COVERAGE:
        fail(f"the photos cover {covered:.5f} of the corridor minus the no-fly zones, "
             f"less than {MIN_COVERAGE}")
    swaths = unary_union([seg_line.buffer(side / 2, cap_style="flat")
                          for l in lane_lines
                          for seg_line in (LineString(p) for p in zip(l.coords, list(l.coords)[1:]))
                          if seg_line.length > 0])
    ratio = swaths.intersection(free).area / free.area
    summary["swath_coverage"] = ratio
    if abs(ratio - stats["coverage_ratio"]) > 0.002:
        fail(f"swath coverage {ratio:.5f} differs from plan.json {stats['coverage_ratio']:.5f}")
    summary["lane_m"] = sum(l.length for l in lane_lines)
    print(json.dumps(summary))


def check_parallel(a, b, centre, where):
    """A lane segment keeps its distance from the line: sampled along it,
    the distances differ by at most PARALLEL_TOL_M plus 2 % (the chord of a
    lane's arc round the outside of a bend, drawn every 20°, dips 1.5 % of
    the offset towards the line)."""
    if math.dist(a, b) < 1.0:
        return
    d = [centre.distance(Point(a[0] + (b[0] - a[0]) * k / 10, a[1] + (b[1] - a[1]) * k / 10))
         for k in range(11)]
    spread = max(d) - min(d)
    if spread > PARALLEL_TOL_M + 0.02 * max(d):
        fail(f"{where}: lane segment {a} -> {b} is {min(d):.2f} to {max(d):.2f} m from the "
             f"centre line: not along it")


if __name__ == "__main__":
    main()
