#!/usr/bin/env python3
"""The synthetic DEM of the scale benchmarks (bench-costmap-tiled.sh,
bench-scale.sh): hills, 0.2 m kerbs, 3 m pockets walled 0.5 m high and
nodata specks on 0.1 m cells in UTM 33N, a tiled Float32 GeoTIFF written
512 rows at a time (fixed seed: the same file every time, so either script
reuses the other's). Run with /usr/bin/python3 (Debian's numpy and GDAL):

    /usr/bin/python3 scripts/bench_dem.py PATH N
"""

import os
import sys


def generate_dem(path, n):
    """Writes the n x n Float32 DEM to `path` (via `path`.part, renamed
    when complete)."""
    import numpy as np
    from osgeo import gdal, osr
    gdal.UseExceptions()
    drv = gdal.GetDriverByName("GTiff")
    ds = drv.Create(path + ".part", n, n, 1, gdal.GDT_Float32,
                    ["TILED=YES", "BLOCKXSIZE=512", "BLOCKYSIZE=512", "BIGTIFF=IF_NEEDED"])
    cell = 0.1
    ds.SetGeoTransform([400000.0, cell, 0.0, 4500000.0 + n * cell, 0.0, -cell])
    srs = osr.SpatialReference()
    srs.ImportFromEPSG(32633)
    ds.SetProjection(srs.ExportToWkt())
    band = ds.GetRasterBand(1)
    band.SetNoDataValue(-9999.0)
    x = np.arange(n, dtype=np.float64) * cell
    rng = np.random.default_rng(22)
    rows = 512
    for r0 in range(0, n, rows):
        r1 = min(n, r0 + rows)
        y = (np.arange(r0, r1, dtype=np.float64) * cell)[:, None]
        z = (100.0 + 0.03 * x[None, :] + 0.02 * y
             + 1.5 * np.sin(x[None, :] / 37.0) * np.cos(y / 23.0)
             + 0.4 * np.sin(x[None, :] / 5.3 + y / 7.1))
        # Kerbs 0.2 m high every 40 m, walls 0.5 m around 3 m pockets every 25 m.
        z += 0.2 * ((x[None, :] % 40.0) > 20.0)
        cx, cy = x[None, :] % 25.0, y % 25.0
        wall = (((np.abs(cx - 10.0) < 0.15) | (np.abs(cx - 13.0) < 0.15))
                & (cy > 10.0) & (cy < 13.0))
        wall |= (((np.abs(cy - 10.0) < 0.15) | (np.abs(cy - 13.0) < 0.15))
                 & (cx > 10.0) & (cx < 13.0))
        z += 0.5 * wall
        z += 0.01 * rng.random(z.shape)
        z[rng.random(z.shape) < 1e-4] = -9999.0
        band.WriteArray(z.astype(np.float32), 0, r0)
    band.FlushCache()
    ds = None
    os.rename(path + ".part", path)


if __name__ == "__main__":
    generate_dem(sys.argv[1], int(sys.argv[2]))
