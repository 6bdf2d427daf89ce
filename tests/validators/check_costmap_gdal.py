"""Independent check of `terraplan costmap` output against GDAL.

usage: check_costmap_gdal.py DEM OUTDIR [--max-rms 3] [--min-agree 95]
                             [--max-slope 25] [--seed 1]

OUTDIR is the --out directory of `terraplan costmap DEM --layers slope ...`.
Runs with Debian's python3-gdal (/usr/bin/python3).

1. Slope: `gdaldem slope` (Horn; `-s 111120` when the DEM's CRS is
   geographic) on DEM into a temporary file, compared with terraplan's
   OUTDIR/layers/slope.tif (degrees) on the valid interior cells (both
   finite, a 2-cell border left out): RMS and mean difference (terraplan
   minus gdaldem), and the agreement in % of the slope-only obstacle mask
   (slope >= max_slope). Fails when RMS > max-rms or agreement < min-agree.
2. OUTDIR/costmap.tif read with GDAL: 2 bands, both Float32; geotransform
   equal to the DEM's within 1e-9 relative; same CRS (osr IsSame); band 1
   nodata NaN; band 1 NaN exactly where band 2 (class) != 1 (traversable);
   and `gdallocationinfo -valonly` at ~10 random pixels (half of them
   chosen among finite costs) gives the values ReadAsArray reads (NaN where
   NaN).

Prints one JSON line with the figures; exit 1 with the reasons on stderr
when a check fails.
"""
import argparse
import json
import math
import os
import random
import subprocess
import sys
import tempfile

import numpy as np
from osgeo import gdal, osr

gdal.UseExceptions()

BORDER = 2


def read_band(ds, index):
    """Band `index` of `ds` as float64 with its nodata value turned into NaN.
    The caller keeps `ds` alive (GDAL 3.6 bindings)."""
    band = ds.GetRasterBand(index)
    arr = band.ReadAsArray().astype(np.float64)
    nodata = band.GetNoDataValue()
    if nodata is not None and not math.isnan(nodata):
        arr[arr == nodata] = np.nan
    return arr


def srs_of(ds):
    wkt = ds.GetProjection()
    if not wkt:
        return None
    srs = osr.SpatialReference()
    srs.ImportFromWkt(wkt)
    srs.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
    return srs


def is_geographic(srs):
    if srs is None:
        return False
    if srs.IsCompound():
        horiz = srs.Clone()
        horiz.StripVertical()
        return bool(horiz.IsGeographic())
    return bool(srs.IsGeographic())


def same_geotransform(a, b):
    scale = max(abs(a[1]), abs(a[5]), abs(b[1]), abs(b[5]))
    for x, y in zip(a, b):
        if abs(x - y) > 1e-9 * max(abs(x), abs(y), scale):
            return False
    return True


def same_value(listed, read):
    """`listed`: a value printed by gdallocationinfo; `read`: the array's."""
    if math.isnan(read) or math.isnan(listed):
        return math.isnan(read) and math.isnan(listed)
    # Both are Float32 cells: equal once rounded to Float32 (gdallocationinfo
    # prints more digits than a Float32 holds).
    return np.float32(listed) == np.float32(read)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dem")
    ap.add_argument("outdir")
    ap.add_argument("--max-rms", type=float, default=3.0)
    ap.add_argument("--min-agree", type=float, default=95.0)
    ap.add_argument("--max-slope", type=float, default=25.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()

    problems = []
    result = {"dem": os.path.basename(args.dem)}

    dem_ds = gdal.Open(args.dem)
    dem_srs = srs_of(dem_ds)
    dem_gt = dem_ds.GetGeoTransform()
    geographic = is_geographic(dem_srs)
    result["geographic"] = geographic
    result["size"] = [dem_ds.RasterXSize, dem_ds.RasterYSize]

    # --- 1. slope against gdaldem -------------------------------------
    with tempfile.TemporaryDirectory(prefix="check_costmap_gdal_") as tmp:
        ref_path = os.path.join(tmp, "slope_gdaldem.tif")
        cmd = ["gdaldem", "slope", "-q", "-alg", "Horn"]
        if geographic:
            cmd += ["-s", "111120"]
        cmd += [args.dem, ref_path]
        run = subprocess.run(cmd, capture_output=True, text=True)
        if run.returncode != 0:
            print(f"{' '.join(cmd)} failed: {run.stderr}", file=sys.stderr)
            sys.exit(1)
        ref_ds = gdal.Open(ref_path)
        ref = read_band(ref_ds, 1)
        ref_ds = None

    slope_path = os.path.join(args.outdir, "layers", "slope.tif")
    if not os.path.exists(slope_path):
        print(f"{slope_path} is missing (run with --layers slope)", file=sys.stderr)
        sys.exit(1)
    tp_ds = gdal.Open(slope_path)
    if tp_ds.RasterCount != 1:
        problems.append(f"layers/slope.tif has {tp_ds.RasterCount} bands, not 1")
    tp_band = tp_ds.GetRasterBand(1)
    if gdal.GetDataTypeName(tp_band.DataType) != "Float32":
        problems.append(
            f"layers/slope.tif is {gdal.GetDataTypeName(tp_band.DataType)}, not Float32")
    nd = tp_band.GetNoDataValue()
    if nd is None or not math.isnan(nd):
        problems.append(f"layers/slope.tif nodata is {nd}, not NaN")
    if not same_geotransform(tp_ds.GetGeoTransform(), dem_gt):
        problems.append(
            f"layers/slope.tif geotransform {tp_ds.GetGeoTransform()} != DEM's {dem_gt}")
    tp = read_band(tp_ds, 1)
    tp_ds = None

    if tp.shape != ref.shape:
        print(f"layers/slope.tif is {tp.shape[1]}x{tp.shape[0]}, the DEM "
              f"{ref.shape[1]}x{ref.shape[0]}", file=sys.stderr)
        sys.exit(1)

    inner = np.zeros(tp.shape, dtype=bool)
    if tp.shape[0] > 2 * BORDER and tp.shape[1] > 2 * BORDER:
        inner[BORDER:-BORDER, BORDER:-BORDER] = True
    valid = inner & np.isfinite(tp) & np.isfinite(ref)
    n = int(valid.sum())
    result["cells"] = n
    if n == 0:
        problems.append("no interior cell where both slopes are finite")
        result.update(rms_deg=None, mean_diff_deg=None, agree_pct=None)
    else:
        d = tp[valid] - ref[valid]
        rms = float(np.sqrt(np.mean(d * d)))
        mask_tp = tp[valid] >= args.max_slope
        mask_ref = ref[valid] >= args.max_slope
        agree = 100.0 * float(np.mean(mask_tp == mask_ref))
        result.update(
            rms_deg=round(rms, 4),
            mean_diff_deg=round(float(d.mean()), 4),
            max_abs_diff_deg=round(float(np.abs(d).max()), 4),
            agree_pct=round(agree, 3),
            max_slope_deg=args.max_slope,
            steep_cells_terraplan=int(mask_tp.sum()),
            steep_cells_gdaldem=int(mask_ref.sum()),
            mean_slope_terraplan_deg=round(float(tp[valid].mean()), 4),
            mean_slope_gdaldem_deg=round(float(ref[valid].mean()), 4),
        )
        if rms > args.max_rms:
            problems.append(f"slope RMS difference {rms:.3f} deg > {args.max_rms}")
        if agree < args.min_agree:
            problems.append(
                f"slope mask (>= {args.max_slope} deg) agreement {agree:.2f} % < {args.min_agree}")

    # --- 2. costmap.tif -------------------------------------------------
    cm_path = os.path.join(args.outdir, "costmap.tif")
    cm_ds = gdal.Open(cm_path)
    if cm_ds.RasterCount != 2:
        problems.append(f"costmap.tif has {cm_ds.RasterCount} bands, not 2")
    for i in range(1, cm_ds.RasterCount + 1):
        t = gdal.GetDataTypeName(cm_ds.GetRasterBand(i).DataType)
        if t != "Float32":
            problems.append(f"costmap.tif band {i} is {t}, not Float32")
    if (cm_ds.RasterXSize, cm_ds.RasterYSize) != (dem_ds.RasterXSize, dem_ds.RasterYSize):
        problems.append(
            f"costmap.tif is {cm_ds.RasterXSize}x{cm_ds.RasterYSize}, the DEM "
            f"{dem_ds.RasterXSize}x{dem_ds.RasterYSize}")
    cm_gt = cm_ds.GetGeoTransform()
    if not same_geotransform(cm_gt, dem_gt):
        problems.append(f"costmap.tif geotransform {cm_gt} != DEM's {dem_gt}")
    cm_srs = srs_of(cm_ds)
    if dem_srs is None or cm_srs is None:
        problems.append("costmap.tif or the DEM has no CRS")
    elif not cm_srs.IsSame(dem_srs):
        # A compound DEM CRS: the costmap may carry the horizontal part only.
        horiz = dem_srs.Clone()
        if not (dem_srs.IsCompound() and horiz.StripVertical() == 0
                and cm_srs.IsSame(horiz)):
            problems.append(
                f"costmap.tif CRS {cm_srs.GetName()} is not the DEM's {dem_srs.GetName()}")
    nd1 = cm_ds.GetRasterBand(1).GetNoDataValue()
    if nd1 is None or not math.isnan(nd1):
        problems.append(f"costmap.tif band 1 nodata is {nd1}, not NaN")

    bands = [cm_ds.GetRasterBand(i).ReadAsArray().astype(np.float64)
             for i in range(1, cm_ds.RasterCount + 1)]
    result["locations_checked"] = 0
    if len(bands) >= 2:
        cost, cls = bands[0], bands[1]
        mismatch = np.isnan(cost) != (cls != 1)
        result["nan_class_mismatches"] = int(mismatch.sum())
        if mismatch.any():
            r, c = np.argwhere(mismatch)[0]
            problems.append(
                f"band 1 NaN must be exactly where band 2 != 1: {int(mismatch.sum())} "
                f"cells differ, first at pixel {c},{r} (cost {cost[r, c]}, class {cls[r, c]})")
        finite_cls = cls[np.isfinite(cls)]
        bad_cls = ~np.isin(finite_cls, [0, 1, 2, 3, 4, 5])
        if bad_cls.any():
            problems.append(f"band 2 has classes outside 0..5: {np.unique(finite_cls[bad_cls])[:10]}")
        result["traversable_pct"] = round(100.0 * float(np.mean(cls == 1)), 3)

        rng = random.Random(args.seed)
        h, w = cost.shape
        picks = [(rng.randrange(w), rng.randrange(h)) for _ in range(5)]
        finite = np.argwhere(np.isfinite(cost))
        for _ in range(5):
            if len(finite):
                r, c = finite[rng.randrange(len(finite))]
                picks.append((int(c), int(r)))
            else:
                picks.append((rng.randrange(w), rng.randrange(h)))
        for (px, py) in picks:
            run = subprocess.run(
                ["gdallocationinfo", "-valonly", cm_path, str(px), str(py)],
                capture_output=True, text=True)
            if run.returncode != 0:
                problems.append(f"gdallocationinfo {px} {py} failed: {run.stderr.strip()}")
                continue
            lines = run.stdout.split()
            if len(lines) != len(bands):
                problems.append(
                    f"gdallocationinfo {px} {py} printed {run.stdout!r}, expected {len(bands)} values")
                continue
            for i, (txt, arr) in enumerate(zip(lines, bands), start=1):
                listed = float(txt)
                if not same_value(listed, float(arr[py, px])):
                    problems.append(
                        f"pixel {px},{py} band {i}: gdallocationinfo {txt}, "
                        f"ReadAsArray {arr[py, px]}")
            result["locations_checked"] += 1
    cm_ds = None
    dem_ds = None

    result["ok"] = not problems
    print(json.dumps(result))
    if problems:
        for p in problems:
            print(p, file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
