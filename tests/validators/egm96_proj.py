"""EGM96 geoid undulations from PROJ (GDAL's osgeo.osr, Debian's
python3-gdal) with the EGM96 15' grid that Debian's proj-data ships
(/usr/share/proj/egm96_15.gtx): nothing of terraplan's, so it checks the
heights of terraplan's GeoJSON independently.

usage: egm96_proj.py < POINTS   (one "lon lat" per line, degrees)
Prints one undulation N per line (metres of the geoid above the WGS 84
ellipsoid: ellipsoidal height = height above mean sea level + N)."""
import sys

from osgeo import gdal, osr

gdal.UseExceptions()

GRID = "/usr/share/proj/egm96_15.gtx"


def undulation_function():
    """N(lon, lat): PROJ's transformation from WGS 84 + EGM96 height
    (EPSG:4326+5773) to WGS 84 3D (EPSG:4979) of a point on the geoid.
    Without the grid PROJ would fall back to no vertical shift, so that is
    refused, and the result is checked at a test point of NGA's EGM96
    program F477 (N = 17.329 m at 0.4667440 S, 0.0023000 E)."""
    try:
        open(GRID, "rb").close()
    except OSError:
        sys.exit(f"{GRID} is missing: install Debian's proj-data (scripts/setup.sh --with-validators)")
    src = osr.SpatialReference()
    src.SetFromUserInput("EPSG:4326+5773")
    src.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
    dst = osr.SpatialReference()
    dst.ImportFromEPSG(4979)
    dst.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
    opts = osr.CoordinateTransformationOptions()
    opts.SetBallparkAllowed(False)
    ct = osr.CoordinateTransformation(src, dst, opts)

    def n(lon, lat):
        return ct.TransformPoint(lon, lat, 0.0)[2]

    ref = n(0.0023, -0.466744)
    if abs(ref - 17.329) > 0.1:
        sys.exit(f"PROJ's EGM96 undulation at NGA's test point is {ref:.3f} m, not 17.329 m")
    return n


if __name__ == "__main__":
    n = undulation_function()
    for line in sys.stdin:
        if line.strip():
            lon, lat = map(float, line.split())
            print(f"{n(lon, lat):.4f}")
