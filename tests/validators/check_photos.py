"""Independent check of a terraplan survey's planned photos (issue 20 item
5), written against shapely, pyproj and numpy only (none of terraplan's
code).

For every UAV's `<uav>.photos.geojson` in OUT_DIR:

- the count: one Feature per photo, as many as plan.json's `photos` for
  the UAV (and in all, the survey's);
- the missions (where the `.waypoints` are there, read by pymavlink): the
  cameras of each sortie's photos are, in order and within 5 cm, where its
  mission takes them (every trigger distance, or interval × speed, from a
  lane's start where triggering starts, floor((length + 1 cm) / spacing) + 1 per
  lane; at the waypoint before each IMAGE_START_CAPTURE);
- the camera: each lane's photos (grouped by sortie and `lane`) lie on one
  line along their `heading_deg` (within 0.05°), `camera_pitch_deg` is
  the requested one, times rise through each sortie and end before its
  flight time;
- the footprints: the corner rays and the centre ray of a pinhole camera
  (PARAMS' `camera`, or the Phantom 4 Pro default) rotated by the tilt
  about the across-track axis and turned to the heading (numpy), met with
  the level ground at take-off height (no DEM) or taken from GROUND.json,
  the ray–DEM intersections check_photos_dem.py computed with GDAL (rays
  grazing a roof's edge for less than a quarter cell, at most 1 % of them,
  as it explains); every
  corner of the file's footprint must lie within 1 % of its ray's range
  (plus 5 cm) of the independent one, and its GSD within 1 %;
- coverage: the union of the independent footprints covers at least
  MIN_COVERAGE (default 0.995) of the free area (ROI minus NFZs);
- the cells' figures: from the independent footprints, per cell, the front
  overlap of consecutive photos of a lane (the share of a footprint's
  length, on the line through its centre along the lane, that the next
  footprint covers), the side overlap (the share of its width, on the
  line through its centre across the lanes, that the footprints of the
  nearest lanes beside it cover, on each side where one of their
  footprints crosses that line: lanes farther across than 5 % of its width
  and within twice it, nearest first, up to a quarter width beyond the
  first with a photo abeam; lanes of one set are those within 1° of each
  other's direction, a lane's place across them the mean of its photos'
  centres; in a cell of more than 20 000 photos every k-th photo)
  and the GSD, as minimum and median; each must match the cell's figures
  in plan.json within OVERLAP_TOL (0.01 on level ground, 0.02 over a DEM)
  and 1 % for the GSD.

usage: check_photos.py OUT_DIR PARAMS.json ROI.geojson [NFZ.geojson ...]
                       [--ground GROUND.json] [--min-coverage X]
Prints a JSON summary; exits 1 with a message on the first failed check.
"""
import argparse
import json
import math
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import shapely
from pymavlink import mavutil, mavwp
from pyproj import Transformer
from shapely.geometry import LineString, Polygon

sys.path.insert(0, str(Path(__file__).parent))
from camera_rays import rays  # noqa: E402
from clearance import read_zones  # noqa: E402


from photo_rule import photo_count  # noqa: E402

DEFAULT_CAMERA = {"sensor_width_mm": 13.2, "sensor_height_mm": 8.8, "focal_length_mm": 8.8,
                  "image_width_px": 5472, "image_height_px": 3648}
CORNER_TOL = 0.01
CORNER_FLOOR_M = 0.05
MAX_SIDE_PHOTOS = 20000
LONG = 1.0e5


def fail(msg):
    print(f"check_photos: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


ML = mavutil.mavlink
POSITIONS = (ML.MAV_CMD_NAV_WAYPOINT, ML.MAV_CMD_NAV_LAND, ML.MAV_CMD_NAV_VTOL_LAND)
STATION_TOL_M = 0.05


def along(lane, s):
    """The point `s` metres (horizontally) along the polyline `lane`."""
    for a, b in zip(lane, lane[1:]):
        seg = math.hypot(b[0] - a[0], b[1] - a[1])
        if s <= seg or b is lane[-1]:
            t = min(s / seg, 1.0) if seg > 0 else 0.0
            return (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t)
        s -= seg
    return lane[-1]


def mission_stations(path, fwd):
    """Where a `.waypoints` mission (read by pymavlink) takes its photos:
    every trigger distance (or interval × speed) from each lane's start,
    floor(length / spacing) + 1 of them, the lane running from the
    waypoint where triggering starts to the one where it stops; and at the
    waypoint before each IMAGE_START_CAPTURE."""
    loader = mavwp.MAVWPLoader()
    loader.load(str(path))
    out, lane, spacing, speed, last = [], None, None, None, None

    def close_lane():
        pts = [p for p in lane if p is not None]
        length = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(pts, pts[1:]))
        n = photo_count(length, spacing)
        out.extend(along(pts, k * spacing) for k in range(n))

    for i in range(1, loader.count()):
        w = loader.wp(i)
        c = w.command
        if c in POSITIONS:
            last = fwd(w.y, w.x)
            if lane is not None:
                lane.append(last)
        elif c == ML.MAV_CMD_DO_CHANGE_SPEED:
            speed = w.param2
        elif c == ML.MAV_CMD_DO_SET_CAM_TRIGG_INTERVAL:
            spacing = w.param1 / 1000.0 * speed
        elif c in (ML.MAV_CMD_DO_SET_CAM_TRIGG_DIST, ML.MAV_CMD_DO_TRIGGER_CONTROL):
            on = w.param1 > 0 if c == ML.MAV_CMD_DO_SET_CAM_TRIGG_DIST else w.param1 == 1
            if on:
                lane = [last]
                if c == ML.MAV_CMD_DO_SET_CAM_TRIGG_DIST:
                    spacing = w.param1
            elif lane is not None:
                close_lane()
                lane = None
        elif c == ML.MAV_CMD_IMAGE_START_CAPTURE:
            out.append(last)
    return out


def span(poly, origin, direction):
    """Where the line through origin along the unit direction crosses
    poly, as (first, last) distances along it; None if it misses."""
    o, d = np.asarray(origin), np.asarray(direction)
    line = LineString([tuple(o - LONG * d), tuple(o + LONG * d)])
    cut = line.intersection(poly)
    if cut.is_empty or cut.length <= 0:
        return None
    ts = [float(np.dot(np.asarray(c) - o, d)) for c in shapely.get_coordinates(cut)]
    return min(ts), max(ts)


def union_length(pieces):
    total, end = 0.0, -math.inf
    for s, e in sorted(pieces):
        s = max(s, end)
        if e > s:
            total += e - s
        end = max(end, e)
    return total


def min_median(v):
    return (min(v), float(np.median(v))) if v else (None, None)


def cell_figures(lanes):
    """Front and side overlap and GSD samples of one cell's lanes, each a
    list of dicts with 'poly', 'centre', 'dir', 'gsd'."""
    front = []
    for lane in lanes:
        for a, b in zip(lane, lane[1:]):
            own = span(a["poly"], a["centre"], a["dir"])
            nxt = span(b["poly"], a["centre"], a["dir"])
            if own is None:
                continue
            shared = 0.0 if nxt is None else max(0.0, min(own[1], nxt[1]) - max(own[0], nxt[0]))
            front.append(shared / (own[1] - own[0]))
    sets = []
    for k, lane in enumerate(lanes):
        d = lane[0]["dir"]
        for s in sets:
            if abs(float(np.dot(s[0], d))) >= math.cos(math.radians(1.0)):
                s[1].append(k)
                break
        else:
            sets.append((d, [k]))
    # A cell of many photos: every stride-th photo (in file order) measured.
    total = sum(len(lane) for lane in lanes)
    stride = max(1, math.ceil(total / MAX_SIDE_PHOTOS))
    first = np.cumsum([0] + [len(lane) for lane in lanes])
    side = []
    for d, members in sets:
        across = np.array([-d[1], d[0]])
        offsets = {k: np.mean([np.dot(p["centre"], across) for p in lanes[k]]) for k in members}
        for k in members:
            for n, p in enumerate(lanes[k]):
                if (first[k] + n) % stride:
                    continue
                own = span(p["poly"], p["centre"], across)
                if own is None:
                    continue
                width = own[1] - own[0]
                for sign in (1.0, -1.0):
                    # The lanes on this side up to a quarter width beyond
                    # the nearest, whether or not that one reaches abeam
                    # (past a no-fly zone a joined cell wraps around, the
                    # next lane is not a neighbour); a sample when one of
                    # them has a photo abeam.
                    cands = sorted((sign * (offsets[j] - offsets[k]), j) for j in members
                                   if j != k and 0.05 * width < sign * (offsets[j] - offsets[k]) <= 2.0 * width)
                    covered, abeam = [], False
                    nearest = cands[0][0] if cands else None
                    for gap, j in cands:
                        if gap > nearest + 0.25 * width:
                            break
                        for q in lanes[j]:
                            sp = span(q["poly"], p["centre"], across)
                            if sp is None:
                                continue
                            abeam = True
                            lo, hi = max(sp[0], own[0]), min(sp[1], own[1])
                            if hi > lo:
                                covered.append((lo, hi))
                    if abeam:
                        side.append(union_length(covered) / width)
    gsd = [p["gsd"] for lane in lanes for p in lane]
    return front, side, gsd


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("params")
    ap.add_argument("roi")
    ap.add_argument("nfz", nargs="*")
    ap.add_argument("--ground")
    ap.add_argument("--min-coverage", type=float, default=0.995)
    args = ap.parse_args()
    out = Path(args.out)
    params = json.loads(Path(args.params).read_text())
    plan = json.loads((out / "plan.json").read_text())
    cam = params.get("camera", DEFAULT_CAMERA)
    pitch = params.get("camera_pitch_deg", -90.0)
    to_utm = Transformer.from_crs("EPSG:4326", f"EPSG:{plan['utm_epsg']}", always_xy=True)
    ground = json.loads(Path(args.ground).read_text()) if args.ground else None
    overlap_tol = 0.02 if ground else 0.01
    gsd_per_m = cam["sensor_width_mm"] / cam["focal_length_mm"] * 100 / cam["image_width_px"]
    if cam.get("orientation") == "portrait":
        gsd_per_m = cam["sensor_height_mm"] / cam["focal_length_mm"] * 100 / cam["image_height_px"]

    def utm(lon, lat):
        return np.array(to_utm.transform(lon, lat))

    summary = {"photos": 0, "worst_corner_error": 0.0, "worst_gsd_error": 0.0}
    by_cell = defaultdict(lambda: defaultdict(list))
    polys = []
    for uav in plan["uavs"]:
        name = f"{uav['id']}.photos.geojson"
        feats = json.loads((out / name).read_text())["features"]
        if len(feats) != uav["stats"]["photos"]:
            fail(f"{name}: {len(feats)} photos, plan.json says {uav['stats']['photos']}")
        summary["photos"] += len(feats)
        times = defaultdict(list)
        for k, ft in enumerate(feats):
            pr = ft["properties"]
            if abs(pr["camera_pitch_deg"] - pitch) > 1e-9:
                fail(f"{name} #{k}: pitch {pr['camera_pitch_deg']}, requested {pitch}")
            lon, lat, z = pr["centre"]
            c = np.array([*utm(lon, lat), z])
            dirs = rays(cam, pitch, pr["heading_deg"])
            if ground:
                hits = [np.array([*utm(g[0], g[1]), g[2]]) for g in ground[name][k]]
            else:
                hits = [c + (c[2] / -d[2]) * d for d in dirs]
            got = [utm(*p) for p in ft["geometry"]["coordinates"][0][:4]]
            for h, g in zip(hits[:4], got):
                rng = float(np.linalg.norm(h - c))
                err = float(np.linalg.norm(h[:2] - g))
                summary["worst_corner_error"] = max(summary["worst_corner_error"], err / rng)
                if err > CORNER_TOL * rng + CORNER_FLOOR_M:
                    fail(f"{name} #{k}: a corner {err:.3f} m from the independent one "
                         f"(range {rng:.1f} m)")
            gsd = float(np.linalg.norm(hits[4] - c)) * gsd_per_m
            gerr = abs(gsd - pr["gsd_cm_px"]) / gsd
            summary["worst_gsd_error"] = max(summary["worst_gsd_error"], gerr)
            if gerr > 0.01:
                fail(f"{name} #{k}: GSD {pr['gsd_cm_px']}, independent {gsd:.4f}")
            poly = Polygon([tuple(h[:2]) for h in hits[:4]])
            polys.append(poly)
            hd = math.radians(pr["heading_deg"])
            by_cell[pr["cell"]][(uav["id"], pr["sortie"], pr["lane"])].append({
                "poly": poly, "centre": hits[4][:2], "camera": c,
                "dir": np.array([math.sin(hd), math.cos(hd)]), "gsd": gsd})
            times[pr["sortie"]].append(pr["time_s"])
        for s, ts in times.items():
            if any(b < a - 1e-6 for a, b in zip(ts, ts[1:])):
                fail(f"{name}: the times of sortie {s} do not rise")
            flown = uav["sorties"][s - 1]["stats"]["flight_time_s"]
            if ts[-1] > flown + 1e-6:
                fail(f"{name}: a photo at {ts[-1]} s of sortie {s}, flown in {flown} s")
    if ground:
        # Rays that graze a roof's edge for less than a quarter cell (see
        # check_photos_dem.py): at most 1 % of them.
        summary["grazes"] = ground["grazes"]
        if ground["grazes"] > 0.01 * 5 * summary["photos"]:
            fail(f"{ground['grazes']} of {5 * summary['photos']} rays pass a roof's edge")
    # The cameras where each sortie's mission takes its photos (when the
    # missions are there: the CLI's output directory).
    stations_checked = 0
    for uav in plan["uavs"]:
        feats = json.loads((out / f"{uav['id']}.photos.geojson").read_text())["features"]
        for k, sortie in enumerate(uav["sorties"]):
            # The service's answer names no file stems (its missions are URLs).
            wp = out / f"{sortie.get('file_stem')}.waypoints"
            if "file_stem" not in sortie or not wp.exists():
                continue
            want = mission_stations(wp, lambda lon, lat: tuple(utm(lon, lat)))
            got = [utm(*f["properties"]["centre"][:2]) for f in feats
                   if f["properties"]["sortie"] == k + 1]
            if len(got) != len(want):
                fail(f"{wp.name}: the mission takes {len(want)} photos, photos.geojson has {len(got)}")
            for n, (g, w) in enumerate(zip(got, want)):
                if math.hypot(g[0] - w[0], g[1] - w[1]) > STATION_TOL_M:
                    fail(f"{wp.name}: photo {n} at {tuple(g)}, the mission takes it at {w}")
            stations_checked += len(want)
    summary["photos_matched_to_missions"] = stations_checked
    if summary["photos"] != plan["stats"]["photos"]:
        fail(f"{summary['photos']} photos in the files, {plan['stats']['photos']} in the plan")

    # Each lane on one line along its heading.
    for lanes in by_cell.values():
        for key, lane in lanes.items():
            if len(lane) < 2:
                continue
            a, b = lane[0]["camera"][:2], lane[-1]["camera"][:2]
            bearing = math.degrees(math.atan2(b[0] - a[0], b[1] - a[1]))
            want = math.degrees(math.atan2(lane[0]["dir"][0], lane[0]["dir"][1]))
            off = (bearing - want + 180) % 360 - 180
            if abs(off) > 0.05:
                fail(f"lane {key}: photos along {bearing:.3f}°, heading {want:.3f}°")

    project = lambda g: shapely.transform(  # noqa: E731
        g, lambda x, y: to_utm.transform(x, y), interleaved=False)
    free = project(read_zones([args.roi]))
    nfz = read_zones(args.nfz) if args.nfz else None
    if nfz is not None:
        free = free.difference(project(nfz))
    seen = shapely.union_all([p.buffer(0) for p in polys])
    coverage = free.intersection(seen).area / free.area
    summary["coverage"] = coverage
    if coverage < args.min_coverage:
        fail(f"the footprints cover {coverage:.5f} of the free area, less than {args.min_coverage}")

    cells = plan["cells"]
    if isinstance(cells, dict):
        # The service's answer: a FeatureCollection, the figures as properties.
        cells = [{"id": f["properties"]["id"],
                  "photos": f["properties"] if "gsd_cm_px_min" in f["properties"] else None}
                 for f in cells["features"]]
    listed = cells
    cells = {c["id"]: c for c in cells}
    worst = 0.0
    for cell, lanes in by_cell.items():
        front, side, gsd = cell_figures(list(lanes.values()))
        mine = cells[cell].get("photos")
        if mine is None:
            fail(f"cell {cell}: photos but no figures in plan.json")
        if mine["photos"] != len(gsd):
            fail(f"cell {cell}: {mine['photos']} photos in plan.json, {len(gsd)} in the files")
        for what, samples in (("front_overlap", front), ("side_overlap", side)):
            lo, med = min_median(samples)
            for stat, v in (("min", lo), ("median", med)):
                theirs = mine[f"{what}_{stat}"]
                if (v is None) != (theirs is None):
                    fail(f"cell {cell}: {what}_{stat} {theirs} in plan.json, independent {v}")
                if v is not None:
                    worst = max(worst, abs(v - theirs))
                    if abs(v - theirs) > overlap_tol:
                        fail(f"cell {cell}: {what}_{stat} {theirs} in plan.json, independent {v:.4f}")
        lo, med = min_median(gsd)
        for stat, v in (("min", lo), ("median", med)):
            if abs(v - mine[f"gsd_cm_px_{stat}"]) > 0.01 * v:
                fail(f"cell {cell}: gsd_cm_px_{stat} {mine[f'gsd_cm_px_{stat}']}, independent {v:.4f}")
    summary["worst_overlap_error"] = worst
    summary["cells"] = len(by_cell)
    summary["min_front_overlap"] = min(
        (c["photos"]["front_overlap_min"] for c in listed
         if c.get("photos") and c["photos"]["front_overlap_min"] is not None), default=None)
    summary["min_side_overlap"] = min(
        (c["photos"]["side_overlap_min"] for c in listed
         if c.get("photos") and c["photos"]["side_overlap_min"] is not None), default=None)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
