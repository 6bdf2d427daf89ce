"""A DEM's first band as float64 heights, nodata as NaN: shared by the
checkers that read DEMs with GDAL."""
import numpy as np


def heights(ds):
    """The heights of the GDAL dataset `ds` (its band 1), nodata as NaN."""
    band = ds.GetRasterBand(1)
    arr = band.ReadAsArray().astype(np.float64)
    nodata = band.GetNoDataValue()
    if nodata is not None:
        arr[arr == nodata] = np.nan
    return arr
