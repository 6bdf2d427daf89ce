#!/usr/bin/env bash
# Installs what terraplan needs on a fresh machine, once; later runs are quick.
#   - cmake, a C++ compiler and SQLite, to build the bundled PROJ (proj-sys);
#   - the web page (web-ui/): its npm packages (npm ci) and its build
#     (web-ui/dist), redone when the lockfile or a source file changes;
#   - a Python venv in .venv with the external validators the tests use,
#     GDAL, and Debian's Chromium for the browser tests (with
#     --with-validators).
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v cmake >/dev/null 2>&1 || need_apt+=(cmake)
command -v sqlite3 >/dev/null 2>&1 || need_apt+=(sqlite3)
command -v g++ >/dev/null 2>&1 || need_apt+=(g++)
command -v npm >/dev/null 2>&1 || need_apt+=(nodejs npm)
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
  # PROJ's EGM96 grid: the independent geoid undulations the GeoJSON
  # heights are checked against (tests/validators/egm96_proj.py).
  [ -e /usr/share/proj/egm96_15.gtx ] || need_gdal+=(proj-data)
  # curl: the DEM tests check that it hears the server's early refusals.
  command -v curl >/dev/null 2>&1 || need_gdal+=(curl)
  # zip: the browser test of the page's GIS import zips a Shapefile.
  command -v zip >/dev/null 2>&1 || need_gdal+=(zip)
  if [ "${#need_gdal[@]}" -gt 0 ]; then
    echo "setup: installing ${need_gdal[*]} with apt-get" >&2
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_gdal[@]}" >/dev/null
  fi
  stamp=".venv/.requirements-$(cat tests/validators/requirements.txt tests/validators/requirements-nodeps.txt \
    | sha1sum | cut -c1-12)"
  if [ ! -f "$stamp" ]; then
    echo "setup: creating .venv with the test validators" >&2
    python3 -m venv .venv
    .venv/bin/pip install --quiet --disable-pip-version-check -r tests/validators/requirements.txt
    .venv/bin/pip install --quiet --disable-pip-version-check --no-deps \
      -r tests/validators/requirements-nodeps.txt
    touch "$stamp"
  fi
fi

if [ "${1:-}" = "--with-validators" ] && [ ! -x /usr/bin/chromium ]; then
  # The browser tests drive Debian's Chromium through playwright-core
  # (Playwright's own browser download is not used).
  echo "setup: installing chromium with apt-get" >&2
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi

# The web page: packages from the lockfile, then the build, each redone
# only when its inputs changed.
lock_stamp="web-ui/node_modules/.terraplan-lock-$(sha1sum web-ui/package-lock.json | cut -c1-12)"
if [ ! -f "$lock_stamp" ]; then
  echo "setup: installing the web page's npm packages" >&2
  # The versions of package-lock.json (`--no-save` leaves it as it is).
  # Not `npm ci`: the registry here has none of the other platforms'
  # optional builds (rollup's, esbuild's), so the lockfile cannot list
  # them and `npm ci` refuses it as out of sync.
  (cd web-ui && npm install --no-save --no-audit --no-fund --loglevel=error)
  touch "$lock_stamp"
fi
if [ ! -f web-ui/dist/index.html ] || [ -n "$(find web-ui/src web-ui/index.html web-ui/package-lock.json \
    web-ui/vite.config.ts web-ui/tsconfig.json -newer web-ui/dist/index.html -print -quit)" ]; then
  echo "setup: building the web page (web-ui/dist)" >&2
  (cd web-ui && npm run --silent build >/dev/null)
fi
