"""Independent check of a terrain-following survey against the DEM, with
GDAL (osgeo, Debian's python3-gdal) doing the reading and the coordinate
transformations, and numpy the bilinear sampling between cell centres.

usage: check_terrain.py DEM SURVEY_JSON UAV_ID WAYPOINTS_FILE [ROUTE_GEOJSON]

SURVEY_JSON is the service's answer to POST /api/v1/surveys (or plan.json).
Checks, for the UAV:
  * the .waypoints file flies exactly the 3D legs the plan reports (after
    converting its altitudes from the mission frame to the DEM's datum);
  * along every flown segment, sampled at half the DEM's cell size, the
    height above the DEM is >= altitude_m - agl_tolerance_m on lanes and
    links and >= transit_clearance_m on transits;
  * with ROUTE_GEOJSON (the UAV's route.geojson), its heights are RFC 7946
    heights: at home and at every waypoint, the height minus the AMSL height
    of the .waypoints file (converted as above) is the EGM96 geoid
    undulation within 0.5 m, the undulation taken from PROJ with the EGM96
    15' grid of Debian's proj-data (egm96_proj.py beside this script), nothing
    of terraplan's; its mission_altitudes_m are the file's altitudes.
Prints JSON: min margins, the fraction of lane length within
+-agl_tolerance_m of altitude_m, sample counts (and the largest GeoJSON
height error). Exit 1 with a message on
the first violation."""
import json
import math
import sys

import numpy as np
from osgeo import gdal, osr

import egm96_proj  # beside this script
from dem_heights import heights  # beside this script

gdal.UseExceptions()


def fail(msg):
    print(msg, file=sys.stderr)
    sys.exit(1)


dem_path, survey_path, uav_id, wp_path = sys.argv[1:5]
route_path = sys.argv[5] if len(sys.argv) > 5 else None
survey = json.load(open(survey_path))
ds = gdal.Open(dem_path)
arr = heights(ds)
gt = ds.GetGeoTransform()
srs = osr.SpatialReference()
srs.ImportFromWkt(ds.GetProjection())
srs.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
wgs = osr.SpatialReference()
wgs.ImportFromEPSG(4326)
wgs.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
if srs.IsCompound():
    srs.StripVertical()  # horizontal positions only
to_dem = osr.CoordinateTransformation(wgs, srs)
det = gt[1] * gt[5] - gt[2] * gt[4]


def dem_height(lon, lat):
    x, y, _ = to_dem.TransformPoint(lon, lat)
    dx, dy = x - gt[0], y - gt[3]
    col = (dx * gt[5] - dy * gt[2]) / det - 0.5
    row = (dy * gt[1] - dx * gt[4]) / det - 0.5
    h, w = arr.shape
    if col < -0.5 or row < -0.5 or col > w - 0.5 or row > h - 0.5:
        return None
    col = min(max(col, 0.0), w - 1.0)
    row = min(max(row, 0.0), h - 1.0)
    c0, r0 = int(math.floor(col)), int(math.floor(row))
    fc, fr = col - c0, row - r0
    total = 0.0
    for (c, r, wgt) in ((c0, r0, (1 - fc) * (1 - fr)), (c0 + 1, r0, fc * (1 - fr)),
                        (c0, r0 + 1, (1 - fc) * fr), (c0 + 1, r0 + 1, fc * fr)):
        if wgt == 0.0:
            continue
        v = arr[r, c]
        if math.isnan(v):
            return None
        total += wgt * v
    return total


# Cell size in metres (local metres per degree for a geographic DEM).
cx, cy = gt[0] + gt[1] * arr.shape[1] / 2, gt[3] + gt[5] * arr.shape[0] / 2
if srs.IsGeographic():
    lat = math.radians(cy)
    res_m = min(abs(gt[1]) * 111320 * math.cos(lat), abs(gt[5]) * 110900)
else:
    res_m = min(abs(gt[1]), abs(gt[5])) * srs.GetLinearUnits()
step = res_m / 2

uav = next(u for u in survey["uavs"] if u["id"] == uav_id)
terrain = uav["sorties"][0]["terrain"]
stats = survey["stats"]
agl = stats["altitude_m"]
tol = stats["terrain"]["agl_tolerance_m"]
clearance = stats["terrain"]["transit_clearance_m"]
frame = survey["altitude_frame"]

# 1. The waypoints file flies the legs.
rows = [l.rstrip("\n").split("\t") for l in open(wp_path).read().splitlines()[1:]]
home_alt = float(rows[0][10])
home_lon, home_lat = float(rows[0][9]), float(rows[0][8])
file_alts = []  # the altitudes as written, in the mission's frame
if abs(home_alt - terrain["home_amsl_m"]) > 1e-3:
    fail(f"home altitude {home_alt} != plan's {terrain['home_amsl_m']}")
flown = []
for r in rows[1:]:
    cmd, fr = int(r[3]), int(r[2])
    if cmd != 16:
        continue
    lat, lon, alt = float(r[8]), float(r[9]), float(r[10])
    file_alts.append(alt)
    if fr == 3:
        z = alt + home_alt
    elif fr == 0:
        z = alt
    elif fr == 10:
        t = dem_height(lon, lat)
        if t is None:
            fail(f"terrain-frame waypoint at {lon},{lat} outside the DEM")
        z = alt + t
    else:
        fail(f"unexpected frame {fr}")
    flown.append((lon, lat, z))
# The mission writer merges a point within 1 cm (3D) of the one before it
# (SAME_POINT_M): the legs describe the flight more finely than the file.
SAME_POINT_M = 0.01
m_lon = 111320 * math.cos(math.radians(flown[0][1]))
m_lat = 110900
legs_pts = []
for leg in terrain["legs"]:
    for p in leg["points"]:
        if legs_pts:
            q = legs_pts[-1]
            d3 = math.sqrt(((p[0] - q[0]) * m_lon) ** 2 + ((p[1] - q[1]) * m_lat) ** 2
                           + (p[2] - q[2]) ** 2)
            if d3 < SAME_POINT_M:
                continue
        legs_pts.append(p)
legs_pts = legs_pts[1:]  # the first point is reached by the take-off
if len(legs_pts) != len(flown):
    fail(f"{len(flown)} waypoints in the file, {len(legs_pts)} in the legs")
# Terrain frame: the file's height above the DEM at a waypoint is the
# planner's, converted back with this script's own DEM reading.
ztol = 0.01 if frame != "terrain" else 0.05
for i, (a, b) in enumerate(zip(flown, legs_pts)):
    if abs(a[0] - b[0]) > 1e-7 or abs(a[1] - b[1]) > 1e-7 or abs(a[2] - b[2]) > ztol:
        fail(f"waypoint {i}: file {a} vs plan {b}")

# 2. Heights above the DEM along every leg.
geod_lat = math.radians(flown[0][1])
m_per_deg_lon = 111320 * math.cos(geod_lat)
m_per_deg_lat = 110900
out = {"lane_min_agl": None, "link_min_agl": None, "transit_min_clearance": None,
       "lane_length_m": 0.0, "lane_within_m": 0.0, "samples": 0, "unknown": 0}
for leg in terrain["legs"]:
    kind = leg["kind"]
    pts = leg["points"]
    need = clearance if kind == "transit" else agl - tol
    key = {"lane": "lane_min_agl", "link": "link_min_agl", "transit": "transit_min_clearance"}[kind]
    for a, b in zip(pts, pts[1:]):
        d = math.hypot((b[0] - a[0]) * m_per_deg_lon, (b[1] - a[1]) * m_per_deg_lat)
        n = max(1, math.ceil(d / step))
        for k in range(n + 1):
            t = k / n
            lon, lat = a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t
            z = a[2] + (b[2] - a[2]) * t
            h = dem_height(lon, lat)
            out["samples"] += 1
            if h is None:
                out["unknown"] += 1
                continue
            above = z - h
            if above < need - 1e-6:
                fail(f"{kind} at {lon:.7f},{lat:.7f}: {above:.3f} m above the DEM, needs >= {need}")
            out[key] = above if out[key] is None else min(out[key], above)
            if kind == "lane" and k > 0:
                out["lane_length_m"] += d / n
                if abs(above - agl) <= tol:
                    out["lane_within_m"] += d / n
out["lane_within_fraction"] = out["lane_within_m"] / max(out["lane_length_m"], 1e-9)


# 3. The GeoJSON route's heights are above the WGS 84 ellipsoid.
if route_path is not None:
    route = json.load(open(route_path))
    if route.get("type") != "FeatureCollection" or len(route.get("features", [])) != 1:
        fail("route.geojson: not a FeatureCollection of one Feature")
    feature = route["features"][0]
    props = feature["properties"]
    coords = feature["geometry"]["coordinates"]
    expect = [(home_lon, home_lat, home_alt)] + flown + [(home_lon, home_lat, home_alt)]
    if len(coords) != len(expect):
        fail(f"route.geojson: {len(coords)} positions, expected home, {len(flown)} waypoints, home")
    if props.get("altitude_frame") != frame:
        fail(f"route.geojson: altitude_frame {props.get('altitude_frame')} != {frame}")
    alts = props["mission_altitudes_m"]
    if len(alts) != len(coords):
        fail(f"route.geojson: {len(alts)} mission altitudes for {len(coords)} positions")
    home_in_frame = home_alt if frame == "amsl" else 0.0
    for i, (a, b) in enumerate(zip(alts, [home_in_frame] + file_alts + [home_in_frame])):
        if abs(a - b) > 1e-3:
            fail(f"route.geojson: mission altitude {i} is {a}, the .waypoints file has {b}")
    undulation = egm96_proj.undulation_function()
    worst = 0.0
    for i, (c, (lon, lat, z)) in enumerate(zip(coords, expect)):
        if len(c) != 3:
            fail(f"route.geojson: position {i} {c} has no height")
        if abs(c[0] - lon) > 1e-7 or abs(c[1] - lat) > 1e-7:
            fail(f"route.geojson: position {i} {c} is not the file's {lon},{lat}")
        n = undulation(lon, lat)
        err = c[2] - z - n
        if abs(err) > 0.5:
            fail(f"route.geojson: position {i}: height {c[2]:.3f} - AMSL {z:.3f} = {c[2] - z:.3f} m, "
                 f"EGM96 undulation (PROJ) {n:.3f} m")
        worst = max(worst, abs(err))
    out["geoid_positions"] = len(coords)
    out["geoid_max_error_m"] = worst
    out["egm96_undulation_m"] = undulation(home_lon, home_lat)
print(json.dumps(out))
