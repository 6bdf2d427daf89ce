"""Clearance of a flown mission from no-fly zones and from its inclusion fence.

Written against pymavlink, shapely and pyproj only (none of terraplan's code).
Away from home (take-off and landing are vertical there, so a disc of the
clearance round home is left out), every flown segment must keep at least
the clearance from every NFZ, and stay that far inside the .plan's inclusion
fence; 1 cm is allowed for rounding.

usage: clearance.py CLEARANCE_M MISSION.waypoints MISSION.plan [NFZ.geojson ...]
Prints {"min_nfz_distance_m", "min_fence_distance_m"}; exits 1 with a
message on the first failed check.
"""
import json
import sys
from pathlib import Path

from pymavlink import mavutil, mavwp
from pyproj import Transformer
import shapely
from shapely.geometry import LineString, Point, shape
from shapely.ops import unary_union

TOL_M = 0.01


def utm_epsg(lon, lat):
    return (32600 if lat >= 0 else 32700) + int((lon + 180) // 6) + 1


def read_zones(paths):
    geoms = []
    for path in paths:
        doc = json.loads(Path(path).read_text())
        feats = doc["features"] if doc.get("type") == "FeatureCollection" else [doc]
        for f in feats:
            g = shape(f["geometry"] if f.get("type") == "Feature" else f)
            geoms.append(g if g.is_valid else g.buffer(0))
    return unary_union(geoms) if geoms else None


def check(clearance, pts, nfz, fence_rings, where):
    """pts: the flown polyline in metres (home first); nfz: shapely geometry
    in the same metres or None; fence_rings: inclusion polygons in metres.
    Returns (min NFZ distance, min fence distance) or raises ValueError."""
    flown = [LineString([a, b]) for a, b in zip(pts, pts[1:]) if a != b]
    if not flown:
        return None, None
    away = unary_union(flown).difference(Point(pts[0]).buffer(clearance, quad_segs=64))
    d_nfz = None
    if nfz is not None and not nfz.is_empty and not away.is_empty:
        d_nfz = away.distance(nfz)
        if d_nfz < clearance - TOL_M:
            raise ValueError(f"{where}: the flight comes {d_nfz:.3f} m from a no-fly zone, "
                             f"closer than the clearance of {clearance} m")
    d_fence = None
    for ring in fence_rings:
        for seg in flown:
            if not ring.contains(seg):
                raise ValueError(f"{where}: flown segment {seg.wkt} leaves the inclusion fence")
            d = seg.distance(ring.exterior)
            d_fence = d if d_fence is None else min(d_fence, d)
            if d < clearance - TOL_M:
                raise ValueError(f"{where}: flown segment {seg.wkt} is {d:.3f} m inside the "
                                 f"inclusion fence, less than the clearance of {clearance} m")
    return d_nfz, d_fence


def inclusion_rings(plan_path, fwd):
    plan = json.loads(Path(plan_path).read_text())
    return [shapely.Polygon([fwd(lon, lat) for lat, lon in f["polygon"]])
            for f in plan["geoFence"]["polygons"] if f.get("inclusion")]


def main():
    clearance = float(sys.argv[1])
    wp_path, plan_path = sys.argv[2], sys.argv[3]
    loader = mavwp.MAVWPLoader()
    n = loader.load(wp_path)
    items = [loader.wp(i) for i in range(n)]
    home = items[0]
    fwd = Transformer.from_crs("EPSG:4326", f"EPSG:{utm_epsg(home.y, home.x)}",
                               always_xy=True).transform
    wps = [it for it in items[1:] if it.command == mavutil.mavlink.MAV_CMD_NAV_WAYPOINT]
    pts = [fwd(home.y, home.x)] + [fwd(w.y, w.x) for w in wps] + [fwd(home.y, home.x)]
    zones = read_zones(sys.argv[4:])
    nfz = shapely.transform(zones, fwd, interleaved=False) if zones is not None else None
    try:
        d_nfz, d_fence = check(clearance, pts, nfz, inclusion_rings(plan_path, fwd), wp_path)
    except ValueError as e:
        print(f"clearance: FAIL: {e}", file=sys.stderr)
        sys.exit(1)
    print(json.dumps({"min_nfz_distance_m": d_nfz, "min_fence_distance_m": d_fence}))


if __name__ == "__main__":
    main()
