#!/usr/bin/env bash
# Measured scale (issue 22 item 5): survey throughput through 1, 2 and 3
# `terraplan serve` replicas sharing one throwaway PostgreSQL database
# (scripts/pg-cluster.sh), against one server on the embedded SQLite,
# with 32 concurrent loopback clients (surveys/s, p50/p99, errors, peak RSS
# per replica); then wall time and peak RSS of the CLI costmap of a big
# Float32 DEM (generated as bench-costmap-tiled.sh does, kept in --dem-dir);
# then the same costmap through the service, its tile jobs built by 1, 2 and
# 3 processes (a serve and 0-2 `terraplan worker`s on the PostgreSQL
# database): wall time, speed-up, CPU and peak RSS per process.
# Writes target/bench-scale.json.
#
#   bash scripts/bench-scale.sh [--seconds 20] [--clients 32] [--max-replicas 3]
#                               [--dem-size 20000] [--tile-size 1024] [--dem-dir /tmp]
#                               [--service-tile-side 512] [--service-tile-cells N]
#                               [--no-survey] [--no-costmap] [--no-service-costmap]
#   bash scripts/bench-scale.sh --seconds 10 --dem-size 8000   # a quicker run
#
# Needs what `bash scripts/setup.sh --with-validators` installs (cargo,
# PostgreSQL, GDAL's python3-gdal and numpy for the DEM). Every process it
# starts is stopped at exit, Ctrl-C included, and its temp dir removed.
set -euo pipefail
cd "$(dirname "$0")/.."
for a in "$@"; do
  case "$a" in -h|--help) exec /usr/bin/python3 scripts/bench_scale.py --help;; esac
done
# The build in a process group of its own, so Ctrl-C, SIGTERM or SIGHUP to
# this script stops cargo and its rustc children alike (cargo leaves them
# running when signalled alone).
setsid cargo build --release --bin terraplan &
build=$!
trap 'kill -TERM -- "-$build" 2>/dev/null; wait "$build" 2>/dev/null; exit 143' TERM HUP INT
wait "$build"
trap - TERM HUP INT
exec /usr/bin/python3 scripts/bench_scale.py "$@"
