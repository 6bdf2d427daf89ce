"""Measured scale (issue 22 item 5); see bench-scale.sh.

1. Survey throughput through 1, 2 and 3 `terraplan serve` replicas on one
   PostgreSQL database (a throwaway cluster from scripts/pg-cluster.sh),
   against one server on the embedded SQLite: N concurrent clients, each
   POSTing the example survey round-robin over the replicas for a fixed
   time. Surveys/s, p50/p99 latency, errors, peak RSS per replica.
2. The CLI costmap of a big Float32 DEM (generated as
   scripts/bench-costmap-tiled.sh does, and cached under the same name):
   wall time and peak RSS.
3. The same costmap through the service, its tiles spread over 1, 2 and 3
   processes on the PostgreSQL database (one `terraplan serve` and 0, 1, 2
   `terraplan worker`s, one tile at a time each): the DEM uploaded once,
   then one costmap per configuration; wall time from the POST to status
   done, speed-up, CPU seconds and peak RSS per process.

Standard library only; the DEM generator alone (`--generate-dem`, run as
a child under /usr/bin/python3) needs numpy and GDAL's Python bindings.
Every process started is stopped at exit (Ctrl-C included) and the
temporary directory removed.
"""

import argparse
import http.client
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


# ---------------------------------------------------------------- processes

class Processes:
    """Every child started, to stop them all at exit."""

    def __init__(self):
        self.children = []

    def start(self, args, **kw):
        # A session of its own: Ctrl-C reaches the benchmark only, which then
        # stops its children in order (SIGTERM, then SIGKILL).
        p = subprocess.Popen(args, start_new_session=True, **kw)
        self.children.append(p)
        return p

    def stop(self, p, grace=10.0):
        if p.poll() is None:
            try:
                p.send_signal(signal.SIGTERM)
                p.wait(grace)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
            except ProcessLookupError:
                pass
        if p in self.children:
            self.children.remove(p)

    def stop_all(self):
        for p in list(reversed(self.children)):
            self.stop(p, grace=5.0)


def raise_interrupt(signum, _frame):
    raise KeyboardInterrupt(f"signal {signum}")


def peak_rss_mib(pid):
    """VmHWM of a live process, MiB (None when unreadable)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return None


def cpu_seconds(pid):
    """User + system CPU time of a live process so far, seconds."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


def machine_cpu():
    """(busy, total) jiffies of all CPUs so far, from /proc/stat."""
    values = [int(v) for v in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    idle = values[3] + (values[4] if len(values) > 4 else 0)
    return sum(values) - idle, sum(values)


def reset_peak_rss(pid):
    """Reset VmHWM to the current RSS (Linux >= 4.0, needs the right to write
    /proc/PID/clear_refs), so each run's peak is its own. False if not."""
    try:
        Path(f"/proc/{pid}/clear_refs").write_text("5")
        return True
    except OSError:
        return False


class Server:
    """A `terraplan serve` on a port of its own, its log in a file."""

    def __init__(self, procs, binary, name, workdir, env_extra, extra_args):
        self.name = name
        data = workdir / f"data-{name}"
        data.mkdir(parents=True)
        self.log_path = workdir / f"{name}.log"
        env = dict(os.environ, NO_COLOR="1", TERRAPLAN_LOG_FORMAT="text", **env_extra)
        env.pop("TERRAPLAN_PORT", None)
        self.proc = procs.start(
            [str(binary), "serve", "--host", "127.0.0.1", "--port", "0",
             "--data-dir", str(data), *extra_args],
            stdout=subprocess.PIPE, stderr=open(self.log_path, "wb"), env=env, text=True)
        first = self.proc.stdout.readline().strip()
        if not first.startswith("listening on http://"):
            self.proc.wait(5)
            tail = self.log_path.read_text(errors="replace")[-2000:]
            raise SystemExit(f"{name}: did not start (first line {first!r}); log:\n{tail}")
        hostport = first.removeprefix("listening on http://")
        self.host, port = hostport.rsplit(":", 1)
        self.port = int(port)
        # Keep reading stdout (the first start's admin line, …) so it never blocks.
        threading.Thread(target=lambda: self.proc.stdout.read(), daemon=True).start()

    @property
    def pid(self):
        return self.proc.pid


def make_token(binary, env_extra, data_dir=None):
    args = [str(binary), "user", "create", f"bench-{os.getpid()}"]
    if data_dir is not None:
        args += ["--data-dir", str(data_dir)]
    run = subprocess.run(args, capture_output=True, text=True,
                         env=dict(os.environ, **env_extra))
    if run.returncode != 0:
        raise SystemExit(f"terraplan user create failed: {run.stderr.strip()}")
    return run.stdout.strip().splitlines()[-1]


# ---------------------------------------------------------------- survey load

def survey_body():
    """The e2e tests' example survey (tests/src/lib.rs example_survey_request):
    the example field with its no-fly zones, lanes at 0 degrees."""
    ex = ROOT / "examples"
    return json.dumps({
        "name": "bench-scale",
        "roi": json.loads((ex / "field.geojson").read_text()),
        "no_fly_zones": [json.loads((ex / "field-nfz.geojson").read_text())],
        "slice_angle_deg": 0,
    }).encode()


def load(servers, token, clients, seconds, warmup, body):
    """`clients` threads POST /api/v1/surveys round-robin over `servers` for
    warmup + seconds; the requests started after the warm-up and answered
    before its end are counted."""
    headers = {"Authorization": f"Bearer {token}", "Content-Type": "application/json"}
    start = time.monotonic()
    measure_from = start + warmup
    end = measure_from + seconds
    lock = threading.Lock()
    latencies, errors, shown = [], [0], []
    statuses = {}

    def client(i):
        conns = [None] * len(servers)
        k = i
        while True:
            began = time.monotonic()
            if began >= end:
                break
            s = k % len(servers)
            k += 1
            try:
                if conns[s] is None:
                    conns[s] = http.client.HTTPConnection(servers[s].host, servers[s].port,
                                                          timeout=180)
                conns[s].request("POST", "/api/v1/surveys", body=body, headers=headers)
                r = conns[s].getresponse()
                data = r.read()
                status, fault = r.status, None
                if not 200 <= status < 300:
                    fault = f"{servers[s].name}: HTTP {status} {data[:300]!r}"
            except (OSError, http.client.HTTPException) as e:
                if conns[s] is not None:
                    conns[s].close()
                conns[s] = None
                status, fault = "exception", f"{servers[s].name}: {type(e).__name__}: {e}"
            done = time.monotonic()
            if began < measure_from or done > end:
                continue
            with lock:
                statuses[status] = statuses.get(status, 0) + 1
                if fault is None:
                    latencies.append(done - began)
                else:
                    errors[0] += 1
                    if len(shown) < 5:
                        shown.append(fault)
        for c in conns:
            if c is not None:
                c.close()

    threads = [threading.Thread(target=client, args=(i,), daemon=True) for i in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    latencies.sort()

    def pct(p):
        if not latencies:
            return None
        return latencies[min(len(latencies) - 1, int(p / 100 * len(latencies)))] * 1000

    return {
        "ok": len(latencies),
        "surveys_per_s": len(latencies) / seconds,
        "p50_ms": pct(50),
        "p99_ms": pct(99),
        "errors": errors[0],
        "first_errors": shown,
        "statuses": {str(k): v for k, v in statuses.items()},
    }


def run_config(label, servers, token, args, body):
    for s in servers:
        reset_peak_rss(s.pid)
    print(f"  {label}: {args.clients} clients for {args.seconds:g} s "
          f"(+{args.warmup:g} s warm-up)...", file=sys.stderr, flush=True)
    cpu_before = {s.name: cpu_seconds(s.pid) for s in servers}
    machine_before = machine_cpu()
    res = load(servers, token, args.clients, args.seconds, args.warmup, body)
    busy, total = (a - b for a, b in zip(machine_cpu(), machine_before))
    # Over warm-up and measured time alike: the whole run's share.
    res["machine_cpu_busy_pct"] = 100 * busy / total if total else None
    res["cpu_s_per_replica"] = {
        s.name: (cpu_seconds(s.pid) - cpu_before[s.name])
        if cpu_before[s.name] is not None else None for s in servers}
    cores = sum(v for v in res["cpu_s_per_replica"].values() if v is not None)
    res["replica_cores_used"] = cores / (args.warmup + args.seconds)
    res["surveys_per_s_per_replica_core"] = (
        res["surveys_per_s"] / res["replica_cores_used"] if cores else None)
    res["config"] = label
    res["replicas"] = len(servers)
    res["peak_rss_mib"] = {s.name: peak_rss_mib(s.pid) for s in servers}
    return res


def start_cluster(workdir):
    """A throwaway PostgreSQL cluster (scripts/pg-cluster.sh) in the temp dir;
    its URL."""
    start = subprocess.run(["bash", str(ROOT / "scripts/pg-cluster.sh"), "start",
                            str(workdir / "pg")],
                           capture_output=True, text=True, start_new_session=True)
    if start.returncode != 0:
        raise SystemExit(f"pg-cluster.sh start failed: {start.stderr.strip()}")
    return start.stdout.strip().splitlines()[-1]


def survey_bench(args, procs, workdir, binary):
    body = survey_body()
    common = ["--planning-per-minute", "0"]
    results = []

    # Reference: one process on the embedded SQLite.
    env = {"TERRAPLAN_LOG": args.log_level}
    env_sqlite = dict(env)
    os.environ.pop("DATABASE_URL", None)
    single = Server(procs, binary, "sqlite", workdir, env_sqlite, common)
    token = make_token(binary, env_sqlite, data_dir=workdir / "data-sqlite")
    results.append(run_config("single process (SQLite)", [single], token, args, body))
    procs.stop(single.proc)

    # Replicas on one PostgreSQL database, added one at a time.
    url = start_cluster(workdir)
    env_pg = dict(env, DATABASE_URL=url)
    replicas = []
    token = None
    for n in range(1, args.max_replicas + 1):
        replicas.append(Server(procs, binary, f"replica{n}", workdir, env_pg, common))
        if token is None:
            token = make_token(binary, env_pg)
        results.append(run_config(f"{n} replica{'s' if n > 1 else ''} (PostgreSQL)",
                                  list(replicas), token, args, body))
    for r in replicas:
        procs.stop(r.proc)
    return results, url


def print_survey_table(results, args):
    print(f"\nSurveys: POST /api/v1/surveys (examples/field.geojson + field-nfz.geojson), "
          f"{args.clients} clients round-robin over the replicas, {args.seconds:g} s each")
    print(f"{'configuration':<26} {'surveys/s':>9} {'speed-up':>8} {'p50 ms':>8} {'p99 ms':>8} "
          f"{'errors':>6} {'CPU busy':>8} {'cores':>5} {'/s/core':>7}  peak RSS per process (MiB)")
    base = next((r["surveys_per_s"] for r in results if r["replicas"] == 1
                 and "PostgreSQL" in r["config"]), None)
    for r in results:
        up = (f"{r['surveys_per_s'] / base:7.2f}x" if base and "PostgreSQL" in r["config"]
              else f"{'':>8}")
        rss = ", ".join(f"{k} {v:.0f}" if v is not None else f"{k} ?"
                        for k, v in r["peak_rss_mib"].items())
        p50 = f"{r['p50_ms']:8.1f}" if r["p50_ms"] is not None else f"{'-':>8}"
        p99 = f"{r['p99_ms']:8.1f}" if r["p99_ms"] is not None else f"{'-':>8}"
        busy = r["machine_cpu_busy_pct"]
        busy = f"{busy:7.0f}%" if busy is not None else f"{'?':>8}"
        per_core = r["surveys_per_s_per_replica_core"]
        per_core = f"{per_core:7.1f}" if per_core is not None else f"{'?':>7}"
        print(f"{r['config']:<26} {r['surveys_per_s']:9.1f} {up} {p50} {p99} "
              f"{r['errors']:6d} {busy} {r['replica_cores_used']:5.2f} {per_core}  {rss}")
        for e in r["first_errors"]:
            print(f"    error: {e}")


# ---------------------------------------------------------------- costmap

def bench_dem(args, procs):
    """The generated big DEM (made once, kept in --dem-dir)."""
    dem = Path(args.dem_dir) / f"terraplan-bench-dem-{args.dem_size}.tif"
    if not dem.exists():
        print(f"generating {dem} ({args.dem_size} x {args.dem_size} Float32, kept for "
              f"later runs)...", file=sys.stderr, flush=True)
        gen = procs.start(["/usr/bin/python3", str(Path(__file__).resolve().parent / "bench_dem.py"),
                           str(dem), str(args.dem_size)])
        try:
            if gen.wait() != 0:
                raise SystemExit("generating the DEM failed (needs numpy and python3-gdal "
                                 "for /usr/bin/python3)")
        finally:
            procs.stop(gen)
            Path(str(dem) + ".part").unlink(missing_ok=True)
    return dem


def costmap_bench(args, procs, workdir, binary):
    dem = bench_dem(args, procs)
    out = workdir / "costmap"
    print(f"  terraplan costmap {dem.name} --tile-size {args.tile_size}...",
          file=sys.stderr, flush=True)
    log = open(workdir / "costmap.log", "wb")
    began = time.monotonic()
    p = procs.start([str(binary), "costmap", str(dem), "--tile-size", str(args.tile_size),
                     "--out", str(out)], stdout=log, stderr=subprocess.STDOUT)
    # wait4 gives this child's own peak RSS (ru_maxrss, KiB on Linux).
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.monotonic() - began
    p.returncode = os.waitstatus_to_exitcode(status)
    procs.children.remove(p)
    if p.returncode != 0:
        tail = (workdir / "costmap.log").read_text(errors="replace")[-2000:]
        raise SystemExit(f"terraplan costmap failed ({p.returncode}):\n{tail}")
    return {
        "dem": str(dem),
        "dem_size": args.dem_size,
        "cells": args.dem_size ** 2,
        "tile_size": args.tile_size,
        "seconds": wall,
        "cpu_seconds": usage.ru_utime + usage.ru_stime,
        "peak_rss_mib": usage.ru_maxrss / 1024,
        "processes": 1,
    }


def print_costmap(c):
    print(f"\nCostmap: terraplan costmap --tile-size {c['tile_size']} of a "
          f"{c['dem_size']} x {c['dem_size']} Float32 DEM ({c['cells'] / 1e6:.0f} M cells)")
    print(f"{'processes':<10} {'wall s':>8} {'CPU s':>8} {'M cells/s':>9} {'peak RSS MiB':>13}")
    print(f"{1:<10} {c['seconds']:8.1f} {c['cpu_seconds']:8.1f} "
          f"{c['cells'] / 1e6 / c['seconds']:9.2f} {c['peak_rss_mib']:13.0f}")


# ---------------------------------------------------------------- costmap over workers

class Worker:
    """A `terraplan worker` (no HTTP) on the PostgreSQL database, its log in
    a file."""

    def __init__(self, procs, binary, name, workdir, env_extra, extra_args):
        self.name = name
        data = workdir / f"data-{name}"
        data.mkdir(parents=True, exist_ok=True)
        self.log_path = workdir / f"{name}.log"
        env = dict(os.environ, NO_COLOR="1", TERRAPLAN_LOG_FORMAT="text", **env_extra)
        self.proc = procs.start(
            [str(binary), "worker", "--data-dir", str(data), *extra_args],
            stdout=subprocess.PIPE, stderr=open(self.log_path, "wb"), env=env, text=True)
        first = self.proc.stdout.readline().strip()
        if not (first.startswith("worker ") and first.endswith(" ready")):
            self.proc.wait(5)
            tail = self.log_path.read_text(errors="replace")[-2000:]
            raise SystemExit(f"{name}: did not start (first line {first!r}); log:\n{tail}")
        threading.Thread(target=lambda: self.proc.stdout.read(), daemon=True).start()

    @property
    def pid(self):
        return self.proc.pid


def api(server, token, method, path, body=None, content_type="application/json",
        length=None, timeout=3600):
    """One request to `server`; (status, parsed JSON or raw bytes)."""
    headers = {"Authorization": f"Bearer {token}"}
    if body is not None:
        headers["Content-Type"] = content_type
        if length is not None:
            headers["Content-Length"] = str(length)
    conn = http.client.HTTPConnection(server.host, server.port, timeout=timeout)
    try:
        conn.request(method, path, body=body, headers=headers)
        r = conn.getresponse()
        data = r.read()
    finally:
        conn.close()
    try:
        return r.status, json.loads(data)
    except ValueError:
        return r.status, data


def service_costmap_bench(args, procs, workdir, binary, url):
    """The big DEM's costmap through the service, its tiles built by 1, 2, 3
    processes (a serve and 0, 1, 2 workers, --costmap-jobs 1 each)."""
    dem = bench_dem(args, procs)
    env = {"TERRAPLAN_LOG": args.log_level, "DATABASE_URL": url}
    size_mb = dem.stat().st_size // (1024 * 1024) + 1
    common = ["--costmap-jobs", "1", "--costmap-tile-side", str(args.service_tile_side),
              "--costmap-tile-cells", str(args.service_tile_cells),
              "--project-quota-mb", "0", "--project-queued-jobs", "0",
              "--planning-per-minute", "0"]
    serve_args = common + ["--max-dem-mb", str(max(256, size_mb)),
                           "--max-dem-pixels", str(max(args.dem_size ** 2, 64_000_000))]
    server = Server(procs, binary, "costmap-serve", workdir, env, serve_args)
    token = make_token(binary, env)
    print(f"  uploading {dem.name} ({dem.stat().st_size / 2**20:.0f} MiB) to the service...",
          file=sys.stderr, flush=True)
    began = time.monotonic()
    with open(dem, "rb") as f:
        status, up = api(server, token, "POST", "/api/v1/dems", body=f,
                         content_type="image/tiff", length=dem.stat().st_size)
    upload_s = time.monotonic() - began
    if status != 201:
        raise SystemExit(f"the DEM upload failed: HTTP {status}: {str(up)[:500]}")
    dem_id = up["id"]
    upload_rss = peak_rss_mib(server.pid)
    runs = []
    workers = []
    for n in range(1, args.max_replicas + 1):
        while len(workers) < n - 1:
            workers.append(Worker(procs, binary, f"worker{len(workers) + 1}", workdir, env,
                                  common))
        processes = [server, *workers]
        for p in processes:
            reset_peak_rss(p.pid)
        cpu_before = {p.name: cpu_seconds(p.pid) for p in processes}
        print(f"  costmap on {n} process{'es' if n > 1 else ''}...", file=sys.stderr,
              flush=True)
        began = time.monotonic()
        status, job = api(server, token, "POST", "/api/v1/costmaps",
                          body=json.dumps({"dem_id": dem_id, "name": f"bench-{n}"}).encode())
        if status != 202 and status != 201:
            raise SystemExit(f"POST /api/v1/costmaps failed: HTTP {status}: {str(job)[:500]}")
        cid = job["id"]
        peaks = {p.name: 0.0 for p in processes}
        while True:
            time.sleep(0.5)
            for p in processes:
                peaks[p.name] = max(peaks[p.name], peak_rss_mib(p.pid) or 0.0)
            status, job = api(server, token, "GET", f"/api/v1/costmaps/{cid}")
            if status != 200:
                raise SystemExit(f"GET costmap failed: HTTP {status}: {str(job)[:500]}")
            if job["status"] in ("done", "failed"):
                break
        wall = time.monotonic() - began
        if job["status"] != "done":
            raise SystemExit(f"the costmap on {n} processes failed: {job.get('error')}")
        tiles = {}
        for p in processes:
            log = p.log_path.read_text(errors="replace").splitlines()
            tiles[p.name] = sum(1 for line in log if "costmap tile job done" in line
                                and cid in line and "discarded" not in line)
        runs.append({
            "processes": n,
            "seconds": wall,
            "cpu_s": {p.name: (cpu_seconds(p.pid) - cpu_before[p.name])
                      if cpu_before[p.name] is not None else None for p in processes},
            "peak_rss_mib": peaks,
            "tile_jobs_logged": tiles,
        })
        # The next run starts from an empty costmap table: drop this one.
        api(server, token, "DELETE", f"/api/v1/costmaps/{cid}")
    for w in workers:
        procs.stop(w.proc)
    procs.stop(server.proc)
    return {"dem_size": args.dem_size, "cells": args.dem_size ** 2,
            "tile_side": args.service_tile_side, "upload_s": upload_s,
            "upload_peak_rss_mib": upload_rss, "runs": runs}


def print_service_costmap(c, cli):
    print(f"\nCostmap through the service ({c['dem_size']} x {c['dem_size']}, tiles of "
          f"{c['tile_side']}): one serve and 0-2 workers on PostgreSQL, one tile at a time "
          f"each; the DEM uploaded once in {c['upload_s']:.1f} s (serve's peak RSS "
          f"{c['upload_peak_rss_mib'] or 0:.0f} MiB)")
    print(f"{'processes':<10} {'wall s':>8} {'speed-up':>8} {'CPU s':>8}  "
          f"peak RSS per process (MiB); tile jobs logged")
    base = c["runs"][0]["seconds"] if c["runs"] else None
    for r in c["runs"]:
        cpu = sum(v for v in r["cpu_s"].values() if v is not None)
        rss = ", ".join(f"{k} {v:.0f}" for k, v in r["peak_rss_mib"].items())
        tiles = ", ".join(f"{k} {v}" for k, v in r["tile_jobs_logged"].items())
        print(f"{r['processes']:<10} {r['seconds']:8.1f} {base / r['seconds']:7.2f}x "
              f"{cpu:8.1f}  {rss}; {tiles}")
    if cli:
        print(f"CLI (one process, same DEM): {cli['seconds']:.1f} s, "
              f"{cli['peak_rss_mib']:.0f} MiB. Speed-up per added process is bounded by the "
              f"{os.cpu_count()} cores shared with PostgreSQL: in principle each tile is "
              f"independent within a stage (classify, fill, cost; join and finish are one "
              f"job each), so processes on more machines add their cores.")


# ---------------------------------------------------------------- main

def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0,
                        help="measured time of each survey configuration (default 20)")
    parser.add_argument("--warmup", type=float, default=2.0,
                        help="unmeasured load before each (default 2)")
    parser.add_argument("--clients", type=int, default=32)
    parser.add_argument("--max-replicas", type=int, default=3)
    parser.add_argument("--dem-size", type=int, default=20000,
                        help="costmap DEM side, cells (default 20000)")
    parser.add_argument("--tile-size", type=int, default=1024)
    parser.add_argument("--service-tile-side", type=int, default=512,
                        help="--costmap-tile-side of the service's tiled costmap (default 512)")
    parser.add_argument("--service-tile-cells", type=int, default=1_000_000,
                        help="--costmap-tile-cells of the service: costmaps over this many "
                             "cells are built as tile jobs (default 1 000 000)")
    parser.add_argument("--no-service-costmap", action="store_true",
                        help="skip the costmap through the service on 1-3 processes")
    parser.add_argument("--dem-dir", default="/tmp",
                        help="where the generated DEM is kept (default /tmp)")
    parser.add_argument("--no-survey", action="store_true")
    parser.add_argument("--no-costmap", action="store_true")
    parser.add_argument("--log-level", default="info,sqlx=warn",
                        help="TERRAPLAN_LOG of the servers (logs go to the temp dir)")
    parser.add_argument("--binary", default=str(ROOT / os.environ.get(
        "CARGO_TARGET_DIR", "target") / "release/terraplan"))
    parser.add_argument("--out", default=str(ROOT / "target/bench-scale.json"))
    args = parser.parse_args()
    if args.clients < 1 or args.seconds <= 0 or args.max_replicas < 1 or args.dem_size < 16:
        parser.error("--clients, --seconds, --max-replicas must be positive, --dem-size >= 16")
    binary = Path(args.binary)
    if not binary.exists():
        parser.error(f"{binary} is missing: cargo build --release --bin terraplan")

    # Explicitly also SIGINT: a shell starts background jobs with it ignored.
    signal.signal(signal.SIGINT, raise_interrupt)
    signal.signal(signal.SIGTERM, raise_interrupt)
    signal.signal(signal.SIGHUP, raise_interrupt)
    procs = Processes()
    workdir = Path(tempfile.mkdtemp(prefix="terraplan-bench-scale-"))
    workdir.chmod(0o755)  # the PostgreSQL cluster runs as the postgres user
    report = {
        "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "cpus": os.cpu_count(),
        "load_average_at_start": os.getloadavg(),
        "clients": args.clients,
        "seconds": args.seconds,
        "warmup_s": args.warmup,
    }
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} at start; "
          f"temp dir {workdir}", file=sys.stderr, flush=True)
    url = None
    try:
        if not args.no_survey:
            report["surveys"], url = survey_bench(args, procs, workdir, binary)
            print_survey_table(report["surveys"], args)
            print(f"CPU busy: all {os.cpu_count()} CPUs of the machine during the run, other "
                  f"work included; cores: CPU time the server processes used (sum over "
                  f"replicas, warm-up included) per second; /s/core: surveys/s per such core. "
                  f"The clients, the replicas and PostgreSQL share the {os.cpu_count()} CPUs: "
                  f"replicas beyond the cores add throughput only by taking a larger share "
                  f"of a busy machine, not by more cores.", flush=True)
        if not args.no_costmap:
            report["costmap"] = costmap_bench(args, procs, workdir, binary)
            print_costmap(report["costmap"])
        if not args.no_service_costmap:
            if url is None:
                url = start_cluster(workdir)
            report["service_costmap"] = service_costmap_bench(args, procs, workdir, binary, url)
            print_service_costmap(report["service_costmap"], report.get("costmap"))
        report["load_average_at_end"] = os.getloadavg()
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(report, indent=1))
        print(f"\nwritten {args.out}")
    except KeyboardInterrupt:
        print("\ninterrupted: stopping everything started", file=sys.stderr)
        sys.exit(130)
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        procs.stop_all()
        if (workdir / "pg").exists():
            subprocess.run(["bash", str(ROOT / "scripts/pg-cluster.sh"), "stop",
                            str(workdir / "pg")], capture_output=True)
        shutil.rmtree(workdir, ignore_errors=True)


if __name__ == "__main__":
    main()
