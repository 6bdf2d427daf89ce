"""Independent check of a terraplan survey output directory.

Written against pymavlink, shapely and pyproj only (none of terraplan's
code): loads every UAV's .waypoints with pymavlink's MAVWPLoader, compares
item counts and positions with plan.json, and checks in UTM metres that no
flown point or segment enters a no-fly zone or, away from home, comes closer
than the plan's nfz_clearance_m to one or to the inclusion fence, that survey lanes stay in the
ROI (an oblique camera's lanes may overshoot it by the footprint's offset
ahead of the camera, so that its first photo sees the ROI's edge), and
that the lanes' footprints cover the free area.

usage: check_survey.py OUT_DIR ROI.geojson [NFZ.geojson ...]
Prints a JSON summary; exits 1 with a message on the first failed check.
"""
import json
import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from pymavlink import mavutil, mavwp
from pyproj import Transformer
from shapely.geometry import LineString, Point
import shapely
from shapely.ops import unary_union

sys.path.insert(0, str(Path(__file__).parent))
from clearance import check as clearance_check, inclusion_rings, read_zones  # noqa: E402

CMD_WAYPOINT = mavutil.mavlink.MAV_CMD_NAV_WAYPOINT
CMD_TRIGG = mavutil.mavlink.MAV_CMD_DO_SET_CAM_TRIGG_DIST
# Tolerances: positions are written with 8 decimals (≈1 mm); geometry
# checks allow 5 cm for the lon/lat round trip of points on NFZ borders.
POS_TOL_DEG = 1e-6
GEOM_TOL_M = 0.05


def fail(msg):
    print(f"check_survey: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def oblique_overshoot(plan):
    """How far an oblique survey's lanes may run past the ROI: a camera
    pitched forward first sees the ground H·tan(tilt − half the field of
    view along track) ahead of it, so its lanes start (and end) that much
    outside (0 for a nadir camera, or without planned photos)."""
    for uav in plan["uavs"]:
        for sortie in uav["sorties"]:
            cam = (sortie.get("photos") or {}).get("camera")
            if cam:
                tilt = math.radians(90.0 + cam["pitch_deg"])
                near = tilt - math.atan(cam["half_tan"][1])
                return max(0.0, plan["stats"]["altitude_m"] * math.tan(near))
    return 0.0


def main():
    out = Path(sys.argv[1])
    roi_ll = read_zones([sys.argv[2]])
    nfz_ll = read_zones(sys.argv[3:])
    plan = json.loads((out / "plan.json").read_text())
    epsg = plan["utm_epsg"]
    fwd = Transformer.from_crs("EPSG:4326", f"EPSG:{epsg}", always_xy=True).transform

    def project(g):
        return shapely.transform(g, fwd, interleaved=False)

    roi = project(roi_ll)
    # An empty NFZ collection is no NFZ.
    nfz = project(nfz_ll) if nfz_ll is not None and not nfz_ll.is_empty else None
    free = roi.difference(nfz) if nfz is not None else roi
    nfz_core = nfz.buffer(-GEOM_TOL_M) if nfz is not None else None
    roi_grown = roi.buffer(GEOM_TOL_M + oblique_overshoot(plan))

    clearance = plan["stats"].get("nfz_clearance_m", 0.0)
    summary = {"uavs": {}, "nfz_clearance_m": clearance}
    lanes = []
    lane_cells = []
    flights = [(uav, sortie) for uav in plan["uavs"] for sortie in uav["sorties"]]
    for uav, sortie in flights:
        uid = sortie["file_stem"]
        wp_path = out / f"{uid}.waypoints"
        loader = mavwp.MAVWPLoader()
        n = loader.load(str(wp_path))
        expected = 1 + len(sortie["mission"]["items"])
        if n != expected:
            fail(f"{wp_path}: pymavlink loaded {n} items, plan.json has {expected}")
        items = [loader.wp(i) for i in range(n)]
        home = items[0]
        if home.frame != 0 or home.command != CMD_WAYPOINT:
            fail(f"{wp_path}: item 0 is not a home waypoint in frame 0")
        if abs(home.x - uav["start"][1]) > POS_TOL_DEG or abs(home.y - uav["start"][0]) > POS_TOL_DEG:
            fail(f"{wp_path}: home position differs from the UAV start")
        expected_wps = [it for it in sortie["mission"]["items"] if it["kind"] == "waypoint"]
        got_wps = [it for it in items[1:] if it.command == CMD_WAYPOINT]
        if len(got_wps) != len(expected_wps):
            fail(f"{wp_path}: {len(got_wps)} waypoints, plan.json has {len(expected_wps)}")
        for a, b in zip(got_wps, expected_wps):
            if abs(a.x - b["lat"]) > POS_TOL_DEG or abs(a.y - b["lon"]) > POS_TOL_DEG:
                fail(f"{wp_path}: waypoint {a.seq} at ({a.y}, {a.x}) differs from plan.json")
        if items[-1].command != mavutil.mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            fail(f"{wp_path}: the last item is not RTL")

        # The flown polyline: home, waypoints, home.
        pts = [fwd(home.y, home.x)] + [fwd(w.y, w.x) for w in got_wps] + [fwd(home.y, home.x)]
        # Away from home, every flown segment keeps the clearance from
        # every NFZ and stays that far inside the inclusion fence.
        try:
            d_nfz, _ = clearance_check(clearance, pts, nfz, inclusion_rings(out / f"{uid}.plan", fwd), wp_path)
        except ValueError as e:
            fail(str(e))
        if d_nfz is not None:
            summary["min_nfz_distance_m"] = min(summary.get("min_nfz_distance_m", d_nfz), d_nfz)
        if nfz_core is not None:
            for p in pts:
                if nfz_core.contains(Point(p)):
                    fail(f"{wp_path}: flown point {p} is inside a no-fly zone")
            for a, b in zip(pts, pts[1:]):
                seg = LineString([a, b]) if a != b else None
                if seg is not None and seg.intersection(nfz_core).length > 0:
                    fail(f"{wp_path}: segment {a} -> {b} crosses a no-fly zone")
        # Lanes: the waypoint before a trigger-on to the waypoint after it.
        owners = [p["cell"] for p in sortie["pieces"] for _ in range(p["lanes"])]
        first_lane = len(lanes)
        last_wp = None
        trig = None
        for it in items[1:]:
            if it.command == CMD_TRIGG:
                if it.param1 > 0:
                    trig = last_wp
                elif trig is not None:
                    lane = LineString([fwd(trig.y, trig.x), fwd(last_wp.y, last_wp.x)])
                    if not roi_grown.contains(lane):
                        fail(f"{wp_path}: survey lane {lane.wkt} leaves the ROI")
                    lanes.append(lane)
                    trig = None
            elif it.command == CMD_WAYPOINT:
                last_wp = it
        if len(lanes) - first_lane != len(owners):
            fail(f"{wp_path}: {len(lanes) - first_lane} lanes flown, plan.json's pieces have {len(owners)}")
        lane_cells.extend(owners)
        # The KML route parses as XML and holds home, the waypoints, home.
        kml = ET.parse(out / f"{uid}.kml").getroot()
        ns = {"k": "http://www.opengis.net/kml/2.2"}
        coords = kml.find(".//k:LineString/k:coordinates", ns).text.split()
        if len(coords) != len(got_wps) + 2:
            fail(f"{uid}.kml: {len(coords)} route points, expected {len(got_wps) + 2}")
        for c, w in zip(coords[1:], got_wps):
            lon, lat, _ = map(float, c.split(","))
            if abs(lon - w.y) > POS_TOL_DEG or abs(lat - w.x) > POS_TOL_DEG:
                fail(f"{uid}.kml: route point {c} differs from the mission")
        summary["uavs"][uid] = {"items": n, "waypoints": len(got_wps)}

    # Together the UAVs fly every cell exactly once: the lanes flown (read
    # from the .waypoints files) are attributed to cells in flight order by
    # plan.json's pieces, each cell's flown lane length must equal its
    # planned one, and no two flown lanes may overlap.
    flown = {c["id"]: 0.0 for c in plan["cells"]}
    for lane, cell in zip(lanes, lane_cells):
        flown[cell] += lane.length
    for c in plan["cells"]:
        if abs(flown[c["id"]] - c["lane_length_m"]) > 1e-4 * c["lane_length_m"] + 0.05:
            fail(f"cell {c['id']}: {flown[c['id']]:.2f} m of lanes flown, {c['lane_length_m']:.2f} m planned")
    total = sum(l.length for l in lanes)
    merged = unary_union(lanes).length if lanes else 0.0
    if total - merged > 0.05 + 1e-6 * total:
        fail(f"lanes overlap: {total:.2f} m flown, {merged:.2f} m distinct")
    summary["flown_lane_m"] = total
    half = plan["stats"]["footprint_side_m"] / 2.0
    swaths = unary_union([l.buffer(half, cap_style="flat") for l in lanes if l.length > 0])
    ratio = swaths.intersection(free).area / free.area
    summary["coverage_ratio"] = ratio
    summary["free_area_m2"] = free.area
    summary["lanes"] = len(lanes)
    if abs(free.area - plan["stats"]["free_area_m2"]) > 1e-3 * free.area:
        fail(f"free area {free.area:.1f} m² differs from plan.json {plan['stats']['free_area_m2']:.1f}")
    if abs(ratio - plan["stats"]["coverage_ratio"]) > 0.002:
        fail(f"coverage {ratio:.5f} differs from plan.json {plan['stats']['coverage_ratio']:.5f}")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
