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
2. OUTDIR/costmap.tif read with GDAL (osgeo.gdal, and gdalinfo -json
   agreeing): two pages (subdatasets GTIFF_DIR:1 and GTIFF_DIR:2); page 1
   one Float32 band "cost", unit type "cost", nodata NaN; page 2 one Byte
   band "class", no unit type, nodata 0, the class names as CLASS_<code>
   metadata; layers/slope.tif one Float32 band "slope" in "deg", nodata NaN;
   each with a geotransform equal to the DEM's within 1e-9 relative and the
   same CRS (osr IsSame); the cost NaN exactly where the class != 1
   (traversable), classes in 0..5; and `gdallocationinfo -valonly` of both
   pages at ~10 random pixels (half of them chosen among finite costs) gives
   the values ReadAsArray reads (NaN where NaN).

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
# The class codes 0..5 by name, as the class band's metadata lists them.
CLASS_NAMES = ["unknown", "traversable", "slope", "step", "enclosed", "other"]


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
    class_path = f"GTIFF_DIR:2:{cm_path}"
    slope_path = os.path.join(args.outdir, "layers", "slope.tif")
    cm_ds = gdal.Open(cm_path)
    subdatasets = cm_ds.GetMetadata("SUBDATASETS")
    names = sorted(v for k, v in subdatasets.items() if k.endswith("_NAME"))
    if names != [f"GTIFF_DIR:1:{cm_path}", class_path]:
        problems.append(f"costmap.tif pages (subdatasets) are {names}, not cost and class")
    class_ds = gdal.Open(class_path)
    slope_ds = gdal.Open(slope_path)
    # What each raster must hold, as osgeo.gdal reads it: band count, then
    # per band description, data type, unit type ("" = none) and nodata.
    expected = [
        ("costmap.tif", cm_ds, cm_path, [("cost", "Float32", "cost", "nan")]),
        ("costmap.tif page 2", class_ds, class_path, [("class", "Byte", "", 0.0)]),
        ("layers/slope.tif", slope_ds, slope_path, [("slope", "Float32", "deg", "nan")]),
    ]
    band_checks = []
    for name, ds, path, bands_wanted in expected:
        if ds.RasterCount != len(bands_wanted):
            problems.append(f"{name} has {ds.RasterCount} bands, not {len(bands_wanted)}")
            continue
        info = json.loads(subprocess.run(
            ["gdalinfo", "-json", path], capture_output=True, text=True, check=True).stdout)
        for i, (desc, dtype, unit, nodata) in enumerate(bands_wanted, start=1):
            band = ds.GetRasterBand(i)
            got_nodata = band.GetNoDataValue()
            got = (band.GetDescription(), gdal.GetDataTypeName(band.DataType),
                   band.GetUnitType(), got_nodata)
            nodata_ok = (got_nodata is not None and
                         (math.isnan(got_nodata) if nodata == "nan" else got_nodata == nodata))
            if got[:3] != (desc, dtype, unit) or not nodata_ok:
                problems.append(
                    f"{name} band {i}: description, type, unit, nodata {got}, "
                    f"expected {(desc, dtype, unit, nodata)}")
            # gdalinfo -json reports the same (its "unit" only when set).
            j = info["bands"][i - 1]
            j_got = (j.get("description"), j.get("type"), j.get("unit", ""),
                     j.get("noDataValue"))
            j_nodata = "NaN" if nodata == "nan" else nodata
            if j_got != (desc, dtype, unit, j_nodata):
                problems.append(
                    f"{name} band {i}: gdalinfo -json says {j_got}, "
                    f"expected {(desc, dtype, unit, j_nodata)}")
            band_checks.append(f"{name}:{i}:{dtype}:{unit or '-'}")
    result["bands_checked"] = band_checks
    class_names = class_ds.GetRasterBand(1).GetMetadata()
    want_names = {f"CLASS_{i}": n for i, n in enumerate(CLASS_NAMES)}
    if class_names != want_names:
        problems.append(f"class band metadata {class_names}, expected {want_names}")

    for name, ds in [("costmap.tif", cm_ds), ("costmap.tif page 2", class_ds),
                     ("layers/slope.tif", slope_ds)]:
        if (ds.RasterXSize, ds.RasterYSize) != (dem_ds.RasterXSize, dem_ds.RasterYSize):
            problems.append(
                f"{name} is {ds.RasterXSize}x{ds.RasterYSize}, the DEM "
                f"{dem_ds.RasterXSize}x{dem_ds.RasterYSize}")
        gt = ds.GetGeoTransform()
        if not same_geotransform(gt, dem_gt):
            problems.append(f"{name} geotransform {gt} != DEM's {dem_gt}")
        srs = srs_of(ds)
        if dem_srs is None or srs is None:
            problems.append(f"{name} or the DEM has no CRS")
        elif not srs.IsSame(dem_srs):
            # A compound DEM CRS: the costmap may carry the horizontal part only.
            horiz = dem_srs.Clone()
            if not (dem_srs.IsCompound() and horiz.StripVertical() == 0
                    and srs.IsSame(horiz)):
                problems.append(
                    f"{name} CRS {srs.GetName()} is not the DEM's {dem_srs.GetName()}")

    # The raw values (no nodata masking): the class page's 0 is "unknown".
    cost = cm_ds.GetRasterBand(1).ReadAsArray().astype(np.float64)
    cls = class_ds.GetRasterBand(1).ReadAsArray()
    result["locations_checked"] = 0
    if cost.shape == cls.shape:
        mismatch = np.isnan(cost) != (cls != 1)
        result["nan_class_mismatches"] = int(mismatch.sum())
        if mismatch.any():
            r, c = np.argwhere(mismatch)[0]
            problems.append(
                f"cost NaN must be exactly where the class != 1: {int(mismatch.sum())} "
                f"cells differ, first at pixel {c},{r} (cost {cost[r, c]}, class {cls[r, c]})")
        bad_cls = cls > 5
        if bad_cls.any():
            problems.append(f"classes outside 0..5: {np.unique(cls[bad_cls])[:10]}")
        result["traversable_pct"] = round(100.0 * float(np.mean(cls == 1)), 3)
        result["unknown_pct"] = round(100.0 * float(np.mean(cls == 0)), 3)

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
            ok = True
            for path, arr in [(cm_path, cost), (class_path, cls.astype(np.float64))]:
                run = subprocess.run(
                    ["gdallocationinfo", "-valonly", path, str(px), str(py)],
                    capture_output=True, text=True)
                if run.returncode != 0:
                    problems.append(f"gdallocationinfo {path} {px} {py} failed: "
                                    f"{run.stderr.strip()}")
                    ok = False
                    continue
                lines = run.stdout.split()
                if len(lines) != 1 or not same_value(float(lines[0]), float(arr[py, px])):
                    problems.append(
                        f"pixel {px},{py} of {path}: gdallocationinfo {run.stdout!r}, "
                        f"ReadAsArray {arr[py, px]}")
                    ok = False
            result["locations_checked"] += int(ok)
    else:
        problems.append(f"cost {cost.shape} and class {cls.shape} differ in size")
    cm_ds = None
    class_ds = None
    slope_ds = None
    dem_ds = None

    result["ok"] = not problems
    print(json.dumps(result))
    if problems:
        for p in problems:
            print(p, file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
