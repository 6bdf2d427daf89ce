#!/usr/bin/env bash
# Installs what terraplan needs on a fresh machine, once; later runs are quick.
#   - cmake, a C++ compiler and SQLite, to build the bundled PROJ (proj-sys);
#   - a Python venv in .venv with the external validators the tests use,
#     and GDAL (with --with-validators).
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v cmake >/dev/null 2>&1 || need_apt+=(cmake)
command -v sqlite3 >/dev/null 2>&1 || need_apt+=(sqlite3)
command -v g++ >/dev/null 2>&1 || need_apt+=(g++)
[ -e /usr/include/sqlite3.h ] || need_apt+=(libsqlite3-dev)
if [ "${#need_apt[@]}" -gt 0 ]; then
  echo "setup: installing ${need_apt[*]} with apt-get" >&2
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

if [ "${1:-}" = "--with-validators" ]; then
  # GDAL (gdalinfo, gdallocationinfo, gdal_translate, gdalwarp, and its
  # Python bindings in Debian's python3) checks the DEM readers and the
  # terrain-following surveys.
  need_gdal=()
  command -v gdalinfo >/dev/null 2>&1 || need_gdal+=(gdal-bin)
  /usr/bin/python3 -c "import osgeo.gdal, numpy" >/dev/null 2>&1 || need_gdal+=(python3-gdal python3-numpy)
  if [ "${#need_gdal[@]}" -gt 0 ]; then
    echo "setup: installing ${need_gdal[*]} with apt-get" >&2
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_gdal[@]}" >/dev/null
  fi
  stamp=".venv/.requirements-$(sha1sum tests/validators/requirements.txt | cut -c1-12)"
  if [ ! -f "$stamp" ]; then
    echo "setup: creating .venv with the test validators" >&2
    python3 -m venv .venv
    .venv/bin/pip install --quiet --disable-pip-version-check -r tests/validators/requirements.txt
    touch "$stamp"
  fi
fi
