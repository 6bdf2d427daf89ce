#!/usr/bin/env bash
# Times the tiled `terraplan costmap` (issue 22 item 2) on a large Float32
# DEM next to `gdaldem slope` on the same DEM: wall time and peak RSS
# (/usr/bin/time -v, "Maximum resident set size") of each. The DEM is
# generated once (kept for later runs) as a tiled, uncompressed GeoTIFF
# of synthetic ground: 0.1 m cells in UTM 33N, rolling hills, kerbs, walled
# pockets and nodata holes, written band by band so generating it needs
# little memory either.
#
#   bash scripts/bench-costmap-tiled.sh [--size 20000] [--tile-size 1024] [--dir /tmp]
#
# Each run can be wrapped (e.g. to pause other work on a shared machine):
#   WRAP=/work/notes/quiet.sh bash scripts/bench-costmap-tiled.sh
# Needs GDAL's command-line tools and Python bindings (gdal-bin,
# python3-gdal) and /usr/bin/time.
set -euo pipefail
cd "$(dirname "$0")/.."
size=20000
tile=1024
dir=/tmp
while [ $# -gt 0 ]; do
  case "$1" in
    --size) size=$2; shift 2;;
    --tile-size) tile=$2; shift 2;;
    --dir) dir=$2; shift 2;;
    *) echo "unknown argument $1" >&2; exit 2;;
  esac
done
wrap=${WRAP:-}
dem="$dir/terraplan-bench-dem-$size.tif"
out="$dir/terraplan-bench-costmap-$size"
cargo build --release --bin terraplan

if [ ! -f "$dem" ]; then
  echo "generating $dem ($size x $size Float32)..." >&2
  /usr/bin/python3 scripts/bench_dem.py "$dem" "$size"
fi

measure() { # label, command...: prints "label seconds peak_MiB"
  local label=$1; shift
  local log
  log=$(mktemp)
  $wrap /usr/bin/time -v "$@" >/dev/null 2>"$log" || { cat "$log" >&2; exit 1; }
  local wall rss
  wall=$(awk -F': ' '/Elapsed \(wall clock\)/ {print $2}' "$log" \
    | awk -F: '{ if (NF == 3) print $1 * 3600 + $2 * 60 + $3; else print $1 * 60 + $2 }')
  rss=$(awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$log")
  rm -f "$log"
  printf '%-34s %9.1f s %9s MiB\n' "$label" "$wall" "$rss"
}

rm -rf "$out"
echo "DEM $dem: ${size} x ${size} Float32, $(du -h "$dem" | cut -f1)"
measure "terraplan costmap (tiles of $tile)" \
  target/release/terraplan costmap "$dem" --tile-size "$tile" --out "$out"
measure "gdaldem slope" gdaldem slope -q "$dem" "$out/gdaldem-slope.tif"

# The check of issue 22: the tiled map equals the whole-raster map of a
# crop of the DEM on the crop's interior (200 cells from its border: the
# halos, and pockets the crop's border would open).
crop=$(( size < 4000 ? size : 4000 ))
at=$(( (size - crop) / 2 ))
gdal_translate -q -srcwin "$at" "$at" "$crop" "$crop" "$dem" "$out/crop.tif"
target/release/terraplan costmap "$out/crop.tif" --out "$out/crop" >/dev/null 2>&1
/usr/bin/python3 - "$out" "$at" "$crop" <<'EOF'
import sys
import numpy as np
from osgeo import gdal
gdal.UseExceptions()
out, at, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
m = min(200, n // 4)
for page in (1, 2):
    big = gdal.Open(f"GTIFF_DIR:{page}:{out}/costmap.tif")
    small = gdal.Open(f"GTIFF_DIR:{page}:{out}/crop/costmap.tif")
    a = big.GetRasterBand(1).ReadAsArray(at + m, at + m, n - 2 * m, n - 2 * m)
    b = small.GetRasterBand(1).ReadAsArray(m, m, n - 2 * m, n - 2 * m)
    same = np.array_equal(a, b, equal_nan=a.dtype.kind == "f")
    print(f"page {page}: {a.size} interior cells of a {n}x{n} crop "
          f"{'equal' if same else 'DIFFER'} to the whole-raster run of the crop")
    big = small = None
    if not same:
        sys.exit(1)
EOF
