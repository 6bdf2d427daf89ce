"""Benchmark `terraplan costmap` next to `gdaldem slope`: wall time and peak
RSS of each child process, on the largest shared DEM and on a 4000 x 4000
upsample of the opengeos DTM.

usage: /usr/bin/python3 scripts/bench_costmap.py [--runs 3] [--size 4000]

Run by scripts/bench-costmap.sh (which builds the release binary first).
Needs the GDAL command-line tools (gdal-bin) and Python 3.9+ only;
downloads nothing. Environment: TERRAPLAN_BIN (default target/release/terraplan),
TERRAPLAN_SHARED_DATA (default ../shared/data), CARGO_TARGET_DIR.

For each file, `--runs` times, interleaved: `terraplan costmap FILE --out
DIR` and `gdaldem slope FILE OUT.tif` (`-s 111120` for a geographic DEM).
Wall time by perf_counter around the child, peak RSS from os.wait4's
ru_maxrss (which includes this script's own RSS at the fork, ~13 MiB:
measured with `true` and reported as the launcher floor). Targets: terraplan's median time <= half gdaldem's (ratio <= 0.5, issue 21),
terraplan's peak RSS <= 5 x width x height x 4 bytes + 100 MiB. Prints a
table and writes the figures to target/bench-costmap.json.
"""
import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

# No osgeo/numpy here on purpose: a child's ru_maxrss starts at this
# process's RSS (the fork/vfork before exec counts), so the parent is kept
# small and raster facts come from `gdalinfo -json`. The floor is measured
# (`true` run the same way) and reported.

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MIB = 1024 * 1024
# terraplan's whole pipeline in at most this share of gdaldem's slope time.
TIME_RATIO_TARGET = 0.5


def shared_data(rel):
    base = os.environ.get("TERRAPLAN_SHARED_DATA", os.path.join(ROOT, "..", "shared", "data"))
    p = os.path.normpath(os.path.join(base, rel))
    if not os.path.exists(p):
        sys.exit(f"shared test data {p} is missing")
    return p


def target_dir():
    return os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))


def raster_info(path):
    """(width, height, geographic) from `gdalinfo -json`."""
    info = json.loads(subprocess.run(["gdalinfo", "-json", "-nomd", path], check=True,
                                     capture_output=True, text=True).stdout)
    w, h = info["size"]
    wkt = info.get("coordinateSystem", {}).get("wkt", "").lstrip()
    if wkt.startswith(("COMPOUNDCRS", "COMPD_CS")):
        # The horizontal part is the first component.
        wkt = wkt[wkt.index("[") + 1:].lstrip()
        wkt = wkt[wkt.index(",") + 1:].lstrip()
    geographic = wkt.startswith(("GEOGCRS", "GEOGCS", "GEOGRAPHICCRS"))
    return w, h, geographic


def run_child(cmd, log_path):
    """Run `cmd`; returns (wall s, peak RSS MiB, user+sys CPU s)."""
    with open(log_path, "wb") as log:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
        _, status, ru = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        with open(log_path, "rb") as log:
            out = log.read().decode(errors="replace")
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{out}")
    # ru_maxrss is in KiB on Linux.
    return wall, ru.ru_maxrss / 1024.0, ru.ru_utime + ru.ru_stime


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", type=int, default=4000,
                    help="side of the upsampled DTM (default 4000)")
    args = ap.parse_args()

    terraplan = os.environ.get("TERRAPLAN_BIN", os.path.join(target_dir(), "release", "terraplan"))
    if not os.path.exists(terraplan):
        sys.exit(f"{terraplan} is missing: cargo build --release --bin terraplan")
    for tool in ("gdaldem", "gdal_translate"):
        if shutil.which(tool) is None:
            sys.exit(f"{tool} is missing (apt-get install gdal-bin)")

    gdal_version = subprocess.run(["gdalinfo", "--version"], capture_output=True,
                                  text=True).stdout.strip()
    results = []
    with tempfile.TemporaryDirectory(prefix="bench-costmap-") as tmp:
        dtm = shared_data("dems/opengeos_data__elevation_dtm.tif")
        big = os.path.join(tmp, f"opengeos_dtm_{args.size}.tif")
        print(f"making {os.path.basename(big)}: bilinear {args.size}x{args.size} Float32 "
              f"upsample of {os.path.basename(dtm)}", flush=True)
        subprocess.run(["gdal_translate", "-q", "-r", "bilinear", "-outsize", str(args.size),
                        str(args.size), "-ot", "Float32", dtm, big], check=True)
        floor_mib = max(run_child(["true"], os.path.join(tmp, "true.log"))[1]
                        for _ in range(3))
        files = [shared_data("dems/demcompare__srtm_ref.tif"), big]

        for path in files:
            w, h, geographic = raster_info(path)
            name = os.path.basename(path)
            tp_cmd_base = [terraplan, "costmap", path, "--out"]
            gd_cmd = ["gdaldem", "slope", "-q"]
            if geographic:
                gd_cmd += ["-s", "111120"]
            gd_out = os.path.join(tmp, "gdaldem_slope.tif")
            gd_cmd += [path, gd_out]
            tp_runs, gd_runs = [], []
            for i in range(args.runs):
                out_dir = os.path.join(tmp, "costmap_out")
                shutil.rmtree(out_dir, ignore_errors=True)
                tp_runs.append(run_child(tp_cmd_base + [out_dir], os.path.join(tmp, "tp.log")))
                if os.path.exists(gd_out):
                    os.remove(gd_out)
                gd_runs.append(run_child(gd_cmd, os.path.join(tmp, "gd.log")))
                print(f"  {name} run {i + 1}: terraplan {tp_runs[-1][0]:.2f} s "
                      f"{tp_runs[-1][1]:.0f} MiB, gdaldem {gd_runs[-1][0]:.2f} s "
                      f"{gd_runs[-1][1]:.0f} MiB", flush=True)
            tp_med = statistics.median(r[0] for r in tp_runs)
            gd_med = statistics.median(r[0] for r in gd_runs)
            tp_peak = max(r[1] for r in tp_runs)
            gd_peak = max(r[1] for r in gd_runs)
            target_mib = (5 * w * h * 4 + 100 * MIB) / MIB
            ratio = tp_med / gd_med if gd_med > 0 else float("inf")
            results.append({
                "file": name,
                "width": w,
                "height": h,
                "geographic": geographic,
                "runs": args.runs,
                "terraplan_wall_s": [round(r[0], 4) for r in tp_runs],
                "gdaldem_wall_s": [round(r[0], 4) for r in gd_runs],
                "terraplan_cpu_s": [round(r[2], 4) for r in tp_runs],
                "gdaldem_cpu_s": [round(r[2], 4) for r in gd_runs],
                "terraplan_peak_rss_mib": [round(r[1], 1) for r in tp_runs],
                "gdaldem_peak_rss_mib": [round(r[1], 1) for r in gd_runs],
                "terraplan_median_s": round(tp_med, 4),
                "gdaldem_median_s": round(gd_med, 4),
                "time_ratio": round(ratio, 3),
                "terraplan_peak_mib": round(tp_peak, 1),
                "gdaldem_peak_mib": round(gd_peak, 1),
                "memory_target_mib": round(target_mib, 1),
                "time_target_met": ratio <= TIME_RATIO_TARGET,
                "memory_target_met": tp_peak <= target_mib,
            })

    header = ["file", "size", "terraplan s", "gdaldem s", "ratio", "terraplan MiB",
              "gdaldem MiB", "target MiB", "time ok", "mem ok"]
    rows = [[r["file"], f"{r['width']}x{r['height']}", f"{r['terraplan_median_s']:.3f}",
             f"{r['gdaldem_median_s']:.3f}", f"{r['time_ratio']:.2f}",
             f"{r['terraplan_peak_mib']:.0f}", f"{r['gdaldem_peak_mib']:.0f}",
             f"{r['memory_target_mib']:.0f}", "yes" if r["time_target_met"] else "NO",
             "yes" if r["memory_target_met"] else "NO"] for r in results]
    widths = [max(len(header[i]), *(len(row[i]) for row in rows)) for i in range(len(header))]
    print()
    print("  ".join(h.ljust(widths[i]) for i, h in enumerate(header)))
    for row in rows:
        print("  ".join(c.ljust(widths[i]) for i, c in enumerate(row)))
    print(f"(medians of {args.runs} runs, peak RSS = max over runs; time target: ratio <= {TIME_RATIO_TARGET}, "
          "memory target: 5 x width x height x 4 bytes + 100 MiB;"
          f" peak RSS includes a launcher floor of {floor_mib:.0f} MiB, the RSS of `true`"
          " started the same way)")

    report = {
        "terraplan": terraplan,
        "host": {"cpus": os.cpu_count(), "machine": platform.machine(),
                 "gdal": gdal_version},
        "launcher_floor_rss_mib": round(floor_mib, 1),
        "results": results,
    }
    out = os.path.join(target_dir(), "bench-costmap.json")
    os.makedirs(os.path.dirname(out), exist_ok=True)
    with open(out, "w") as f:
        json.dump(report, f, indent=2)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
