"""Independent footprints of a survey's photos over a DEM, for
check_photos.py: GDAL (osgeo, Debian's python3-gdal) reads the DEM and does
the coordinate transformations, numpy samples it bilinearly between cell
centres and casts the rays; nothing of terraplan's.

For every Feature of each PHOTOS.geojson (terraplan's photos.geojson): the
camera at its `centre` (lon, lat, height in the DEM's datum), turned to its
`heading_deg` (grid bearing in the file's `utm_epsg`) and pitched by
`camera_pitch_deg`; the rays of a pinhole camera (CAMERA.json: the request's
`camera`, or the Phantom 4 Pro default) through the image's corners and its
centre are rotated by the tilt about the across-track axis and followed in
steps of a sixteenth of the DEM's cell until they pass under the DEM's
surface, then refined by bisection to 1 mm.

A ray that grazes a roof's edge dips under the surface for a short chord
before it meets the ground beyond; terraplan follows its rays in steps of a
quarter cell and may pass such a chord. Where the file's corner lies
farther along the ray than the first hit, it is accepted only if it lies on
the ray (within 5 cm) and on the DEM's surface (within 5 cm), and every
chord of the ray under the surface before it is shorter than a quarter
cell; such grazes are counted, anything else is reported as the first hit
(and check_photos.py then finds the corner off).

usage: check_photos_dem.py DEM CAMERA.json OUT.json PHOTOS.geojson...
Writes OUT.json: {file name: [[[lon, lat, h] x 5] per feature], "grazes":
count} (near left, near right, far right, far left, centre).
"""
import json
import math
import sys
from pathlib import Path

import numpy as np
from osgeo import gdal, osr

sys.path.insert(0, str(Path(__file__).parent))
from camera_rays import rays  # noqa: E402
from dem_heights import heights as dem_heights  # noqa: E402

gdal.UseExceptions()

DEFAULT_CAMERA = {"sensor_width_mm": 13.2, "sensor_height_mm": 8.8, "focal_length_mm": 8.8,
                  "image_width_px": 5472, "image_height_px": 3648}


def srs_of(epsg=None, wkt=None):
    s = osr.SpatialReference()
    if epsg:
        s.ImportFromEPSG(epsg)
    else:
        s.ImportFromWkt(wkt)
    s.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
    if s.IsCompound():
        s.StripVertical()
    return s


def main():
    dem_path, camera_path, out_path = sys.argv[1:4]
    camera = json.loads(Path(camera_path).read_text()) or DEFAULT_CAMERA
    ds = gdal.Open(dem_path)
    arr = dem_heights(ds)
    gt = ds.GetGeoTransform()
    det = gt[1] * gt[5] - gt[2] * gt[4]
    dem_srs = srs_of(wkt=ds.GetProjection())
    wgs = srs_of(4326)
    rows, cols = arr.shape

    def height(px, py):
        """Bilinear height between cell centres at DEM coordinates."""
        dx, dy = px - gt[0], py - gt[3]
        col = (dx * gt[5] - dy * gt[2]) / det - 0.5
        row = (dy * gt[1] - dx * gt[4]) / det - 0.5
        if col < -0.5 or row < -0.5 or col > cols - 0.5 or row > rows - 0.5:
            return None
        col, row = min(max(col, 0.0), cols - 1.0), min(max(row, 0.0), rows - 1.0)
        c0, r0 = min(int(col), cols - 2), min(int(row), rows - 2)
        fc, fr = col - c0, row - r0
        v = (arr[r0, c0] * (1 - fc) * (1 - fr) + arr[r0, c0 + 1] * fc * (1 - fr)
             + arr[r0 + 1, c0] * (1 - fc) * fr + arr[r0 + 1, c0 + 1] * fc * fr)
        return None if math.isnan(v) else v

    out = {}
    grazes = 0
    for path in sys.argv[4:]:
        doc = json.loads(Path(path).read_text())
        utm = srs_of(doc["properties"]["utm_epsg"])
        to_utm = osr.CoordinateTransformation(wgs, utm)
        to_wgs = osr.CoordinateTransformation(utm, wgs)
        to_dem = osr.CoordinateTransformation(utm, dem_srs)
        # Cell size in metres: a sixteenth of a cell per step.
        lon0, lat0 = doc["features"][0]["properties"]["centre"][:2]
        x0, y0, _ = to_utm.TransformPoint(lon0, lat0)
        a = to_dem.TransformPoint(x0, y0)
        b = to_dem.TransformPoint(x0 + 100.0, y0)
        cell = math.hypot(gt[1], gt[2]) * 100.0 / math.hypot(b[0] - a[0], b[1] - a[1])
        step = cell / 16

        def above(p):
            q = to_dem.TransformPoint(p[0], p[1])
            g = height(q[0], q[1])
            return None if g is None else p[2] - g

        def first_hit(c, d, t_from):
            """First t >= t_from where the ray c + t d meets the surface."""
            t_prev, t = t_from, t_from + step
            while t < 20000.0:
                h = above(c + t * d)
                if h is not None and h <= 0:
                    lo, hi = t_prev, t
                    while hi - lo > 1e-3:
                        mid = (lo + hi) / 2
                        hm = above(c + mid * d)
                        if hm is not None and hm <= 0:
                            hi = mid
                        else:
                            lo = mid
                    return hi
                t_prev, t = t, t + step
            return None

        def graze(c, d, t_hit, corner):
            """The file's corner if it is a later hit past short chords only."""
            t_file = float(np.dot(corner - c, d))
            off = np.linalg.norm(c + t_file * d - corner)
            if t_file <= t_hit + 0.05 or off > 0.05:
                return None
            hc = above(corner)
            if hc is None or abs(hc) > 0.05:
                return None
            t, start = t_hit, t_hit
            while t < t_file - 0.05:
                h = above(c + t * d)
                if h is not None and h > 0:
                    if t - start >= cell / 4:
                        return None
                    nxt = first_hit(c, d, t)
                    if nxt is None or nxt >= t_file - 0.05:
                        return corner
                    t = start = nxt
                else:
                    t += step
            return corner if t - start < cell / 4 else None

        feats = []
        for ft in doc["features"]:
            pr = ft["properties"]
            lon, lat, z = pr["centre"]
            cx, cy, _ = to_utm.TransformPoint(lon, lat)
            c = np.array([cx, cy, z])
            ring = ft["geometry"]["coordinates"][0][:4] + [pr["ground_centre"]]
            heights = pr["ground_heights_m"]
            pts = []
            for k, d in enumerate(rays(camera, pr["camera_pitch_deg"], pr["heading_deg"])):
                t = first_hit(c, d, 0.0)
                if t is None:
                    print(f"{path}: a ray of photo {pr['index']} meets no DEM height", file=sys.stderr)
                    sys.exit(1)
                hit = c + t * d
                fx, fy, _ = to_utm.TransformPoint(ring[k][0], ring[k][1])
                later = graze(c, d, t, np.array([fx, fy, heights[k]]))
                if later is not None:
                    grazes += 1
                    hit = later
                glon, glat, _ = to_wgs.TransformPoint(hit[0], hit[1])
                pts.append([glon, glat, float(hit[2])])
            feats.append(pts)
        out[Path(path).name] = feats
    out["grazes"] = grazes
    Path(out_path).write_text(json.dumps(out))


if __name__ == "__main__":
    main()
