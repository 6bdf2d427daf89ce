#!/usr/bin/env bash
# Builds Fields2Cover 2.1.0 (its PyPI sdist) without OR-tools and the
# benchmark's driver linked to it, into target/f2c/bin/f2c_bench, for
# scripts/bench-coverage.sh; later runs are quick (a stamp). Downloads
# nothing but the sdist and its metadata backend from PyPI (pip) and the
# Debian packages it lacks (apt-get, as scripts/setup.sh does). Usage:
#   bash scripts/f2c/build.sh --steering-functions DIR [--sdist FILE]
# or the same through STEERING_FUNCTIONS_DIR and F2C_SDIST.
#   DIR   Fields2Cover's steering_functions at commit 13e3f565 (the commit
#         Fields2Cover 2.1.0 pins): a source tree, or a git directory holding
#         that commit (it is exported with git archive).
#   FILE  fields2cover-2.1.0.tar.gz (default: pip download from PyPI).
# Exit status 1 with a message naming what is missing.
set -euo pipefail
start=$PWD
cd "$(dirname "$0")/../.."

F2C_VERSION=2.1.0
SF_COMMIT=13e3f5658144b3832fb1eb31a0e2f5a3cbf57db9
DEBS=(cmake g++ make libgdal-dev libgeos-dev libeigen3-dev libtinyxml2-dev
      libtbb-dev nlohmann-json3-dev libboost-dev python3-venv)
out=target/f2c
sf_dir=${STEERING_FUNCTIONS_DIR:-}
sdist=${F2C_SDIST:-}
while [ $# -gt 0 ]; do
  case "$1" in
    --steering-functions) sf_dir=${2:?--steering-functions needs a directory}; shift 2 ;;
    --sdist) sdist=${2:?--sdist needs a file}; shift 2 ;;
    *) echo "build.sh: unknown argument $1" >&2; exit 1 ;;
  esac
done

# Paths given relative to where the script was started from.
case "$sf_dir" in /*|"") ;; *) sf_dir=$start/$sf_dir ;; esac
case "$sdist" in /*|"") ;; *) sdist=$start/$sdist ;; esac
here=scripts/f2c
[ -n "$sdist" ] || sdist=$out/dl/fields2cover-$F2C_VERSION.tar.gz
stamp_of() {
  { echo "$SF_COMMIT"; cat "$sdist" "$here/no-ortools.patch" "$here/F2CUtils.cmake" \
    "$here/CMakeLists.txt" "$here/f2c_bench.cpp"; } | sha1sum | cut -c1-12
}
# Built from these very inputs already: nothing to do (and nothing needed).
if [ -f "$sdist" ] && [ -x "$out/bin/f2c_bench" ] &&
  [ "$(cat "$out/.stamp" 2>/dev/null)" = "$(stamp_of)" ]; then
  exit 0
fi

missing=()
for deb in "${DEBS[@]}"; do
  dpkg-query -W -f='${Status}' "$deb" 2>/dev/null | grep -q "ok installed" \
    || missing+=("$deb")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "build.sh: installing ${missing[*]} with apt-get" >&2
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  { $SUDO apt-get update -qq &&
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null; } ||
    { echo "build.sh: could not install the Debian packages ${missing[*]}" >&2; exit 1; }
fi

if [ -z "$sf_dir" ]; then
  echo "build.sh: missing steering_functions (Fields2Cover's fork, commit" \
    "$SF_COMMIT): pass --steering-functions DIR or set STEERING_FUNCTIONS_DIR" \
    "to its source tree or a git directory holding that commit" >&2
  exit 1
fi
mkdir -p "$out"
if [ -f "$sf_dir/CMakeLists.txt" ] && [ -d "$sf_dir/include/steering_functions" ]; then
  sf_src=$(cd "$sf_dir" && pwd)
elif git --git-dir="$sf_dir" cat-file -e "$SF_COMMIT^{commit}" 2>/dev/null; then
  sf_src=$PWD/$out/steering_functions
  if [ ! -f "$sf_src/.commit" ] || [ "$(cat "$sf_src/.commit")" != "$SF_COMMIT" ]; then
    rm -rf "$sf_src" && mkdir -p "$sf_src"
    git --git-dir="$sf_dir" archive "$SF_COMMIT" | tar -x -C "$sf_src"
    echo "$SF_COMMIT" > "$sf_src/.commit"
  fi
else
  echo "build.sh: $sf_dir is neither a steering_functions source tree" \
    "(CMakeLists.txt, include/steering_functions/) nor a git directory" \
    "holding commit $SF_COMMIT" >&2
  exit 1
fi

if [ "$sdist" = "$out/dl/fields2cover-$F2C_VERSION.tar.gz" ]; then
  if [ ! -f "$sdist" ]; then
    # pip prepares the sdist's metadata, which needs its build backend
    # (scikit-build-core); a small venv of its own keeps that out of others.
    if [ ! -x "$out/pip-venv/bin/pip" ]; then
      python3 -m venv "$out/pip-venv"
      "$out/pip-venv/bin/pip" install --quiet --disable-pip-version-check \
        scikit-build-core==1.1.2
    fi
    "$out/pip-venv/bin/pip" download --quiet --disable-pip-version-check \
      --no-deps --no-binary :all: --no-build-isolation \
      -d "$out/dl" "fields2cover==$F2C_VERSION"
  fi
fi
[ -f "$sdist" ] || { echo "build.sh: no sdist at $sdist" >&2; exit 1; }

stamp=$(stamp_of)
src=$out/src/fields2cover-$F2C_VERSION
rm -rf "$out/src" && mkdir -p "$out/src"
tar -xzf "$sdist" -C "$out/src"
patch --quiet -p1 -d "$src" < "$here/no-ortools.patch"
cp "$here/F2CUtils.cmake" "$src/cmake/F2CUtils.cmake"
cmake -S "$here" -B "$out/build" -DCMAKE_BUILD_TYPE=Release \
  -DF2C_SOURCE_DIR="$PWD/$src" \
  -DFETCHCONTENT_FULLY_DISCONNECTED=ON \
  -DFETCHCONTENT_SOURCE_DIR_STEERING_FUNCTIONS="$sf_src" >"$out/cmake.log" \
  || { tail -30 "$out/cmake.log" >&2; echo "build.sh: cmake configure failed ($out/cmake.log)" >&2; exit 1; }
cmake --build "$out/build" --target f2c_bench -j 2 >"$out/build.log" 2>&1 \
  || { grep -m 20 -E "error|Error" "$out/build.log" >&2; echo "build.sh: build failed ($out/build.log)" >&2; exit 1; }
mkdir -p "$out/bin"
cp "$out/build/f2c_bench" "$out/bin/f2c_bench"
echo "$stamp" > "$out/.stamp"
echo "built $out/bin/f2c_bench (Fields2Cover $F2C_VERSION, no OR-tools)"
