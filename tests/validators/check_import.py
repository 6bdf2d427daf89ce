"""Independent check of a terraplan GIS import against its source geometry.

Written against shapely and pyproj only (none of terraplan's code). Both
files are read as GeoJSON: IMPORTED is `terraplan import`'s output
(`{"features": FeatureCollection, "messages": [...]}`) or a plain
FeatureCollection; TWIN is the geometry the imported file was made from,
in WGS84 (a legacy `crs` member naming CRS84/EPSG:4326 or none).
Both are projected with pyproj into the one UTM zone of TWIN's centroid
and compared there:

- polygons: the areas of the unions agree within REL_TOL (relative);
- lines: the total lengths agree within REL_TOL;
- both: the Hausdorff distance is at most MAX_OFFSET_M. A file written in
  another CRS by GDAL comes back through this build's PROJ, whose datum
  transformation may differ from GDAL's by a fraction of a millimetre.

usage: check_import.py IMPORTED.json TWIN.geojson polygon|line [REL_TOL]
Prints a JSON summary; exits 1 with a message on the first failed check.
"""
import json
import sys

import pyproj
import shapely
from shapely.geometry import shape
from shapely.ops import unary_union

# Largest distance between the import and its twin, metres.
MAX_OFFSET_M = 0.005


def fail(msg):
    print(f"check_import: {msg}", file=sys.stderr)
    sys.exit(1)


def features(doc):
    if "features" in doc and isinstance(doc["features"], dict):
        doc = doc["features"]
    if doc.get("type") == "FeatureCollection":
        return [f["geometry"] for f in doc["features"] if f.get("geometry")]
    if doc.get("type") == "Feature":
        return [doc["geometry"]]
    return [doc]


def flat(g):
    """GeoJSON geometry without third coordinates (KML heights)."""
    def strip(c):
        return [strip(x) for x in c] if isinstance(c[0], list) else c[:2]
    return {"type": g["type"], "coordinates": strip(g["coordinates"])}


def main():
    if len(sys.argv) not in (4, 5):
        fail(__doc__.strip().splitlines()[-2])
    imported = json.load(open(sys.argv[1]))
    twin = json.load(open(sys.argv[2]))
    kind = sys.argv[3]
    rel_tol = float(sys.argv[4]) if len(sys.argv) == 5 else 1e-6
    polygonal = ("Polygon", "MultiPolygon")
    linear = ("LineString", "MultiLineString")
    want = polygonal if kind == "polygon" else linear
    a = [shape(flat(g)) for g in features(imported) if g["type"] in want]
    b = [shape(flat(g)) for g in features(twin) if g["type"] in want]
    if not a or not b:
        fail(f"no {kind} in {'the import' if not a else 'the twin'}")
    ua, ub = unary_union(a), unary_union(b)
    c = ub.centroid
    zone = int((c.x + 180) // 6) + 1
    epsg = (32600 if c.y >= 0 else 32700) + zone
    to_utm = pyproj.Transformer.from_crs(4326, epsg, always_xy=True).transform
    pa = shapely.transform(ua, to_utm, interleaved=False)
    pb = shapely.transform(ub, to_utm, interleaved=False)
    summary = {"utm_epsg": epsg, "parts": [len(a), len(b)]}
    if kind == "polygon":
        rel = abs(pa.area - pb.area) / pb.area
        summary.update(area_m2=[pa.area, pb.area], area_rel_diff=rel)
        if rel > rel_tol:
            fail(f"areas differ: {pa.area} vs {pb.area} m² (relative {rel:.3g} > {rel_tol})")
    else:
        rel = abs(pa.length - pb.length) / pb.length
        summary.update(length_m=[pa.length, pb.length], length_rel_diff=rel)
        if rel > rel_tol:
            fail(f"lengths differ: {pa.length} vs {pb.length} m (relative {rel:.3g})")
    hd = pa.hausdorff_distance(pb)
    summary["hausdorff_m"] = hd
    if hd > MAX_OFFSET_M:
        fail(f"the geometries are {hd} m apart (Hausdorff) > {MAX_OFFSET_M} m")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
