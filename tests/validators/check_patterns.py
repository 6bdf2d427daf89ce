"""Independent check of a terraplan survey's pattern, camera pitch and
trigger (issue 20), written against pymavlink, shapely, pyproj and numpy
only (none of terraplan's code).

From every sortie's `.waypoints` (read by pymavlink's MAVWPLoader):

- lanes are rebuilt from the camera commands: DO_SET_CAM_TRIGG_DIST d > 0
  … 0 (distance), DO_TRIGGER_CONTROL 1 … 0 (time, the interval from
  DO_SET_CAM_TRIGG_INTERVAL); in hover mode every IMAGE_START_CAPTURE must
  follow a held NAV_WAYPOINT;
- photos: per lane floor(length / spacing) + 1 (spacing = the trigger
  distance, or interval × the DO_CHANGE_SPEED speed), or one per
  IMAGE_START_CAPTURE of count 1 in hover; the sum must equal plan.json's;
- the gimbal: DO_GIMBAL_MANAGER_PITCHYAW before the first lane with the
  requested pitch (none when the request sets none);
- crosshatch: each lane belongs to a cell it meets; it is of the first set
  when along that cell's lane bearing, of the second when at 90° ± 1° to
  it (anything else fails); each set's photos alone must see >= 99.5 % of
  the free area (nadir: a footprint_side_m × footprint_front_m rectangle
  at every photo; oblique: the lanes swept at the near-edge width, as the
  plan's coverage figure, since oblique photos land ahead of the lane);
- oblique: the footprint is computed by casting the four corner rays of a
  pinhole camera rotated by the pitch and meeting them with the ground
  plane; its near-edge width and along-track extent, and the spacing and
  trigger distance they give with the requested overlaps, must match
  plan.json's within 1 %.

usage: check_patterns.py OUT_DIR PARAMS.json ROI.geojson [NFZ.geojson ...]
Prints a JSON summary; exits 1 with a message on the first failed check.
"""
import json
import math
import sys
from pathlib import Path

import numpy as np
from pymavlink import mavutil, mavwp
from pyproj import Transformer
from shapely.geometry import LineString, Point, Polygon, shape
import shapely
from shapely.ops import unary_union

sys.path.insert(0, str(Path(__file__).parent))
from clearance import read_zones  # noqa: E402


from photo_rule import photo_count  # noqa: E402

ML = mavutil.mavlink
DEFAULT_CAMERA = {"sensor_width_mm": 13.2, "sensor_height_mm": 8.8, "focal_length_mm": 8.8,
                  "image_width_px": 5472, "image_height_px": 3648}
REL_TOL = 0.01


def fail(msg):
    print(f"check_patterns: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def items(path):
    loader = mavwp.MAVWPLoader()
    loader.load(str(path))
    return [loader.wp(i) for i in range(loader.count())]


def lanes_of(wps, fwd):
    """Lanes (lists of UTM points, each with the distance between its
    photos; none in hover mode), photos, and the gimbal commands as
    (index, pitch, yaw)."""
    lanes, photos, pitches = [], 0, []
    speed = None
    current, spacing, last_pos = None, None, None
    for i, w in enumerate(wps[1:], start=1):
        cmd = w.command
        pos = None
        if cmd == ML.MAV_CMD_NAV_WAYPOINT:
            pos = fwd(w.y, w.x)
        if cmd == ML.MAV_CMD_DO_CHANGE_SPEED:
            speed = w.param2
        elif cmd == ML.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW:
            pitches.append((i, w.param1, w.param2))
        elif cmd == ML.MAV_CMD_DO_SET_CAM_TRIGG_DIST:
            if w.param1 > 0:
                current, spacing = [last_pos], w.param1
            else:
                lanes.append((current, spacing))
                photos += photo_count(length(current), spacing)
                current = None
        elif cmd == ML.MAV_CMD_DO_SET_CAM_TRIGG_INTERVAL:
            spacing = w.param1 / 1000.0 * speed
        elif cmd == ML.MAV_CMD_DO_TRIGGER_CONTROL:
            if w.param1 == 1:
                current = [last_pos]
            else:
                lanes.append((current, spacing))
                photos += photo_count(length(current), spacing)
                current = None
        elif cmd == ML.MAV_CMD_IMAGE_START_CAPTURE:
            prev = wps[i - 1]
            if prev.command != ML.MAV_CMD_NAV_WAYPOINT or prev.param1 <= 0:
                fail(f"item {i}: IMAGE_START_CAPTURE not after a held waypoint")
            if w.param3 != 1:
                fail(f"item {i}: IMAGE_START_CAPTURE of {w.param3} images, not 1")
            photos += 1
        if pos is not None:
            if current is not None:
                current.append(pos)
            last_pos = pos
    return [(lane, d) for lane, d in lanes if lane and len(lane) >= 2], photos, pitches


def length(pts):
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(pts, pts[1:]))


def seen_by(lane, spacing, side, front, pitch):
    """The ground a lane's photos see: nadir, the union of side × front
    rectangles at every photo (every `spacing` from the lane's start);
    oblique, the lane swept at the footprint's near-edge width (its photos
    land ahead of it)."""
    a, b = lane[0], lane[-1]
    line = LineString([a, b])
    if pitch is not None and pitch > -90:
        return line.buffer(side / 2, cap_style="flat")
    n = photo_count(line.length, spacing)
    ux, uy = (b[0] - a[0]) / line.length, (b[1] - a[1]) / line.length
    rects = []
    for k in range(n):
        cx, cy = a[0] + ux * k * spacing, a[1] + uy * k * spacing
        rects.append(Polygon([(cx + ux * f * front / 2 - uy * s * side / 2,
                               cy + uy * f * front / 2 + ux * s * side / 2)
                              for f, s in [(-1, -1), (1, -1), (1, 1), (-1, 1)]]))
    return unary_union(rects)


def bearing(a, b):
    return math.degrees(math.atan2(b[0] - a[0], b[1] - a[1])) % 180.0


def gap(a, b):
    d = (a - b) % 180.0
    return min(d, 180.0 - d)


def ray_footprint(cam, h, pitch):
    """Corners (across, along) of the footprint by ray casting: rays of the
    nadir camera rotated about the across-track axis by the tilt."""
    tilt = math.radians(90.0 + pitch)
    rot = np.array([[1, 0, 0],
                    [0, math.cos(tilt), -math.sin(tilt)],
                    [0, math.sin(tilt), math.cos(tilt)]])
    w, hh, f = cam["sensor_width_mm"] / 2, cam["sensor_height_mm"] / 2, cam["focal_length_mm"]
    if cam.get("orientation") == "portrait":
        w, hh = hh, w
    corners = []
    for sx, sy in [(-w, -hh), (w, -hh), (w, hh), (-w, hh)]:
        ray = rot @ np.array([sx, sy, -f])
        if ray[2] >= 0:
            fail("a corner ray does not meet the ground")
        k = h / -ray[2]
        corners.append((ray[0] * k, ray[1] * k))
    return corners


def close(got, want, what):
    if abs(got - want) > REL_TOL * abs(want):
        fail(f"{what}: plan {got}, independent {want}")


def main():
    out = Path(sys.argv[1])
    params = json.loads(Path(sys.argv[2]).read_text())
    roi_ll = read_zones([sys.argv[3]])
    nfz_ll = read_zones(sys.argv[4:])
    plan = json.loads((out / "plan.json").read_text())
    stats = plan["stats"]
    to_utm = Transformer.from_crs("EPSG:4326", f"EPSG:{plan['utm_epsg']}", always_xy=True)

    def fwd(lon, lat):
        return to_utm.transform(lon, lat)

    def project(g):
        return shapely.transform(g, lambda x, y: to_utm.transform(x, y), interleaved=False)

    free = project(roi_ll)
    if nfz_ll is not None:
        free = free.difference(project(nfz_ll))
    summary = {"sorties": 0, "lanes": 0, "photos": 0}
    all_lanes = []
    pitch = params.get("camera_pitch_deg")
    for uav in plan["uavs"]:
        for sortie in uav["sorties"]:
            wps = items(out / f"{sortie['file_stem']}.waypoints")
            lanes, photos, pitches = lanes_of(wps, fwd)
            if photos != sortie["stats"]["photos"]:
                fail(f"{sortie['file_stem']}: {photos} photos in the mission, "
                     f"{sortie['stats']['photos']} in the plan")
            if pitch is None and pitches:
                fail(f"{sortie['file_stem']}: a gimbal command without camera_pitch_deg")
            if pitch is not None:
                if len(pitches) != 1 or abs(pitches[0][1] - pitch) > 1e-6 or pitches[0][2] != 0:
                    fail(f"{sortie['file_stem']}: gimbal commands {pitches}, want one at {pitch}")
            summary["sorties"] += 1
            summary["lanes"] += len(lanes)
            summary["photos"] += photos
            all_lanes.extend(lanes)
    if summary["photos"] != stats["photos"]:
        fail(f"{summary['photos']} photos in the missions, {stats['photos']} in the plan")

    side = stats["footprint_side_m"]
    hover = params.get("trigger", {}).get("mode") == "hover"
    if params.get("pattern") == "crosshatch" and not hover:
        # plan.json lists the cells; the service's answer holds them as GeoJSON.
        cells = plan["cells"]
        if isinstance(cells, dict):
            cells = [dict(f["properties"], polygon=f["geometry"]) for f in cells["features"]]
        cells = [(project(shape(c["polygon"])), c["lane_bearing_deg"]) for c in cells]
        sets = ([], [])
        worst = 0.0
        for lane in all_lanes:
            a, b = lane[0][0], lane[0][-1]
            line = LineString([a, b])
            lb = bearing(a, b)
            # A lane is its cell's (lanes run on through free space past
            # their cell): the cells it meets, the nearest first.
            near = sorted(cells, key=lambda c: c[0].distance(line.interpolate(0.5, normalized=True)))
            near = [c for c in near if c[0].distance(line) < 1.0] or near[:1]
            # The nearest of them whose lanes run along or across it.
            g = next((g for g in (gap(lb, cb) for _, cb in near)
                      if g < 1.0 or abs(g - 90.0) <= 1.0), None)
            if g is not None and g < 1.0:
                sets[0].append(lane)
            elif g is not None:
                sets[1].append(lane)
                worst = max(worst, abs(g - 90.0))
            else:
                fail(f"lane at {lb:.2f}° in cells of lanes at {[round(c[1], 2) for c in near]}°: "
                     "neither set")
        for k, lanes in enumerate(sets):
            strips = unary_union([seen_by(lane, d, side, stats["footprint_front_m"], pitch)
                                  for lane, d in lanes])
            ratio = free.intersection(strips).area / free.area
            summary[f"set{k + 1}_coverage"] = ratio
            summary[f"set{k + 1}_lanes"] = len(lanes)
            if ratio < 0.995:
                fail(f"lane set {k + 1} alone covers {ratio:.4f} of the free area")
        summary["worst_right_angle_error_deg"] = worst

    if pitch is not None:
        cam = params.get("camera", DEFAULT_CAMERA)
        c = ray_footprint(cam, stats["altitude_m"], pitch)
        near = c[1][0] - c[0][0]
        along = c[2][1] - c[1][1]
        close(stats["footprint_side_m"], near, "near-edge width")
        close(stats["footprint_front_m"], along, "along-track extent")
        if "line_spacing_m" not in params:
            close(stats["line_spacing_m"], near * (1 - params.get("side_overlap", 0.7)), "spacing")
        close(stats["trigger_distance_m"], along * (1 - params.get("front_overlap", 0.8)),
              "trigger distance")
        summary["footprint"] = {"near_width_m": near, "along_m": along,
                                "far_width_m": c[2][0] - c[3][0]}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
