"""Benchmark terraplan's flock assignment against OR-tools' routing solver
and PyVRP on the same routing instances (issue 21, item 3).

usage: bench_flock.py [--instances DIR] [--all] [--only NAME ...]
                      [--ortools-s 5,30] [--pyvrp-s 10] [--json OUT]

Run by scripts/bench-flock.sh (which builds the release binary and the
benchmark's venv first). Downloads nothing. Without --instances the
instances are written by `terraplan experiment flock --instances`
(TERRAPLAN_BIN, default target/release/terraplan) into
target/bench-flock/instances: the thesis experiment's 60 trials (12 cells
over the opengeos DTM round four buildings, 3-8 UAVs, 10 formations).

The instance (see README, "Flock experiment"): nodes are the UAV starts
and the jobs' two ends; travel_s[a][b] is the NFZ-avoiding travel time
(climbs and turns included) of terraplan's own cost model; a job is flown
from either end to the other in duration_s; every UAV returns to its start;
makespan = the longest UAV time. Every solver's routes are costed here by
one function in floating point, so the makespans compare exactly.

- OR-tools (pywrapcp): one node per job and direction ("oriented job": the
  arc into it costs the travel to its entry end plus its duration, the arc
  out of it starts at its exit end), the two in a mandatory disjunction
  (exactly one flown); one vehicle per UAV, starting and ending at its own
  depot; the min-max objective as a global span cost (coefficient 100) on
  a time dimension, with the arcs' sum as the tie-break; first solution
  PATH_CHEAPEST_ARC, then GUIDED_LOCAL_SEARCH for the time limit. Integer
  arc costs in milliseconds (the solution is then costed exactly).
- PyVRP: the same oriented jobs as clients (service time = the duration)
  in required mutually exclusive client groups, one vehicle type per UAV
  with its own depot. PyVRP minimises total cost and has no min-max
  objective, so it "fits" by bisection on a hard shift duration: a first
  unconstrained solve, then limits halfway between a simple lower bound
  and the best makespan found, each solve given an equal share of the
  budget (unit duration cost, so each minimises total time under the cap).

The default run takes a representative subset (see default_subset: 14
instances, about 10 minutes on 2 cores with OR-tools' 35 s and PyVRP's 5 s
each); --all runs all 60 (about 40 minutes).
"""
import argparse
import json
import math
import os
import pathlib
import statistics
import subprocess
import sys
import time
import warnings

ROOT = pathlib.Path(__file__).resolve().parent.parent
TARGET = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
SCALE = 1000  # integer costs in milliseconds


def default_subset(names):
    """14 of the 60: the odd formations with 3 UAVs and the even ones with
    4 (small flocks, where the sharing decides the makespan; with more UAVs
    the dearest single job's round trip often does), and one formation per
    size from 5 to 8 UAVs (e01, e04, e07, e10)."""
    picks = [(3, e) for e in (1, 3, 5, 7, 9)] + [(4, e) for e in (2, 4, 6, 8, 10)]
    picks += [(5, 1), (6, 4), (7, 7), (8, 10)]
    return [x for n, e in picks for x in names if x.startswith(f"n{n}-e{e:02}-")]


def route_time(inst, start, route):
    """A UAV's time: travel plus durations, from its start and back."""
    travel, jobs = inst["travel_s"], inst["jobs"]
    at, t = start, 0.0
    for job, rev in route:
        a, b = jobs[job]["ends"]
        entry, exit_ = (b, a) if rev else (a, b)
        t += travel[at][entry] + jobs[job]["duration_s"]
        at = exit_
    return t + travel[at][start]


def makespan(inst, routes):
    flown = sorted(j for r in routes for j, _ in r)
    if flown != list(range(len(inst["jobs"]))):
        raise ValueError(f"{inst['name']}: routes do not fly every job once")
    return max(route_time(inst, u["start"], r) for u, r in zip(inst["uavs"], routes))


def lower_bound(inst):
    """A simple bound independent of terraplan's: the dearest job's
    cheapest round trip, and the total work shared among the UAVs."""
    travel, jobs, starts = inst["travel_s"], inst["jobs"], [u["start"] for u in inst["uavs"]]
    trips = max(
        min(
            travel[s][j["ends"][w]] + j["duration_s"] + travel[j["ends"][1 - w]][s]
            for s in starts
            for w in (0, 1)
        )
        for j in jobs
    )
    return max(trips, sum(j["duration_s"] for j in jobs) / len(starts))


class Oriented:
    """Nodes 0..m-1: the UAVs' depots; m + 2j + w: job j flown way w (w = 1
    enters at ends[1])."""

    def __init__(self, inst):
        self.inst = inst
        self.m = len(inst["uavs"])
        self.n = len(inst["jobs"])

    def size(self):
        return self.m + 2 * self.n

    def entry_exit(self, node):
        if node < self.m:
            s = self.inst["uavs"][node]["start"]
            return s, s, 0.0
        j, w = divmod(node - self.m, 2)
        a, b = self.inst["jobs"][j]["ends"]
        d = self.inst["jobs"][j]["duration_s"]
        return (b, a, d) if w else (a, b, d)

    def travel(self, a, b):
        """Seconds from leaving node a to leaving node b (b's job flown)."""
        if a == b:
            return 0.0
        _, exit_a, _ = self.entry_exit(a)
        entry_b, _, dur_b = self.entry_exit(b)
        return self.inst["travel_s"][exit_a][entry_b] + dur_b

    def step(self, node):
        j, w = divmod(node - self.m, 2)
        return [j, bool(w)]


def solve_ortools(inst, seconds):
    from ortools.constraint_solver import pywrapcp, routing_enums_pb2

    o = Oriented(inst)
    size, m = o.size(), o.m
    cost = [[round(o.travel(a, b) * SCALE) for b in range(size)] for a in range(size)]
    manager = pywrapcp.RoutingIndexManager(size, m, list(range(m)), list(range(m)))
    routing = pywrapcp.RoutingModel(manager)

    def arc(i, k):
        return cost[manager.IndexToNode(i)][manager.IndexToNode(k)]

    cb = routing.RegisterTransitCallback(arc)
    routing.SetArcCostEvaluatorOfAllVehicles(cb)
    horizon = sum(max(row) for row in cost) + 1
    routing.AddDimension(cb, 0, horizon, True, "time")
    routing.GetDimensionOrDie("time").SetGlobalSpanCostCoefficient(100)
    for j in range(o.n):
        fwd, rev = (manager.NodeToIndex(m + 2 * j + w) for w in (0, 1))
        # Mandatory: exactly one direction of each job is flown.
        routing.AddDisjunction([fwd, rev])
    params = pywrapcp.DefaultRoutingSearchParameters()
    params.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PATH_CHEAPEST_ARC
    params.local_search_metaheuristic = (
        routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    )
    params.time_limit.FromSeconds(seconds)
    t0 = time.perf_counter()
    sol = routing.SolveWithParameters(params)
    elapsed = time.perf_counter() - t0
    if sol is None:
        return None, elapsed, 0
    routes = []
    for v in range(m):
        i, r = sol.Value(routing.NextVar(routing.Start(v))), []
        while not routing.IsEnd(i):
            r.append(o.step(manager.IndexToNode(i)))
            i = sol.Value(routing.NextVar(i))
        routes.append(r)
    return makespan(inst, routes), elapsed, idle(routes)


def idle(routes):
    """UAVs left without work (terraplan gives each UAV some)."""
    return sum(not r for r in routes)


def pyvrp_data(inst, shift_ms=None):
    import numpy as np
    import pyvrp

    o = Oriented(inst)
    size, m = o.size(), o.m
    # Locations in node order; the job's duration is the client's service
    # time, so the matrix holds travel only.
    mat = np.zeros((size, size), dtype=np.int64)
    for a in range(size):
        for b in range(size):
            if a != b:
                _, exit_a, _ = o.entry_exit(a)
                entry_b, _, _ = o.entry_exit(b)
                mat[a, b] = round(inst["travel_s"][exit_a][entry_b] * SCALE)
    locations = [pyvrp.Location(x=0, y=0) for _ in range(size)]
    depots = [pyvrp.Depot(location=u) for u in range(m)]
    clients = [
        pyvrp.Client(
            location=node,
            service_duration=round(o.entry_exit(node)[2] * SCALE),
            required=False,
            group=(node - m) // 2,
        )
        for node in range(m, size)
    ]
    groups = [pyvrp.ClientGroup([2 * j, 2 * j + 1], required=True) for j in range(o.n)]
    limit = {} if shift_ms is None else {"shift_duration": int(shift_ms)}
    vehicles = [
        pyvrp.VehicleType(
            1,
            start_depot=u,
            end_depot=u,
            unit_distance_cost=0,
            unit_duration_cost=1,
            **limit,
        )
        for u in range(m)
    ]
    return pyvrp.ProblemData(locations, clients, depots, vehicles, [mat], [mat], groups), o


def pyvrp_once(inst, seconds, shift_ms):
    import pyvrp
    from pyvrp.stop import MaxRuntime

    data, o = pyvrp_data(inst, shift_ms)
    res = pyvrp.solve(data, stop=MaxRuntime(seconds), seed=1, collect_stats=False)
    if not res.best.is_feasible():
        return None, 0
    routes = [[] for _ in range(o.m)]
    for route in res.best.routes():
        u = route.vehicle_type()
        # Client k is node m + k.
        visits = [a.idx for a in route.schedule() if is_client(a)]
        routes[u] = [o.step(o.m + k) for k in visits]
    return makespan(inst, routes), idle(routes)


def is_client(activity):
    c = activity.is_client
    return c() if callable(c) else c


def solve_pyvrp(inst, seconds, steps=6):
    t0 = time.perf_counter()
    share = seconds / (steps + 1)
    # A cap it cannot meet makes PyVRP warn that its penalties hit their
    # maximum: expected while bisecting.
    warnings.filterwarnings("ignore", module="pyvrp")
    best, idle_uavs = pyvrp_once(inst, share, None)
    lo = lower_bound(inst)
    for _ in range(steps):
        if best is None or best <= lo * (1 + 1e-6):
            break
        cap = (lo + best) / 2
        got, got_idle = pyvrp_once(inst, share, math.floor(cap * SCALE))
        if got is not None and got < best:
            best, idle_uavs = got, got_idle
        else:
            lo = cap
    return best, time.perf_counter() - t0, idle_uavs


def fmt(result):
    """A solver's makespan; * where it left a UAV without work."""
    if result["makespan_s"] is None:
        return "-"
    return f"{result['makespan_s']:.1f}" + ("*" if result["idle_uavs"] else "")


def make_instances(dest):
    exe = os.environ.get("TERRAPLAN_BIN", str(TARGET / "release" / "terraplan"))
    print(f"writing the instances: {exe} experiment flock --instances {dest}", flush=True)
    subprocess.run(
        [exe, "experiment", "flock", "--instances", str(dest)],
        check=True,
        stdout=subprocess.DEVNULL,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--instances", type=pathlib.Path)
    ap.add_argument("--all", action="store_true", help="every instance, not the subset")
    ap.add_argument("--only", nargs="*", default=[], help="instance names")
    ap.add_argument("--ortools-s", default="5,30", help="time limits, comma-separated")
    ap.add_argument("--pyvrp-s", type=float, default=5.0, help="budget; 0 skips PyVRP")
    ap.add_argument("--json", type=pathlib.Path, default=TARGET / "bench-flock.json")
    args = ap.parse_args()
    limits = [int(x) for x in args.ortools_s.split(",") if x]

    folder = args.instances
    if folder is None:
        folder = TARGET / "bench-flock" / "instances"
        make_instances(folder)
    files = {p.stem: p for p in sorted(folder.glob("*.json"))}
    names = args.only or (sorted(files) if args.all else default_subset(sorted(files)))
    if not names:
        sys.exit(f"no instances in {folder}")

    cols = ["instance", "UAVs", "jobs", "bound", "terraplan", "ms"]
    cols += [f"OR {s}s" for s in limits] + (["PyVRP", "s"] if args.pyvrp_s > 0 else [])
    widths = [20, 4, 4, 8, 9, 6] + [9] * len(limits) + ([9, 5] if args.pyvrp_s > 0 else [])
    print("makespans in seconds (every solver's routes costed by one function)")
    print(" ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(cols, widths))))
    rows = []
    for name in names:
        inst = json.loads(files[name].read_text())
        tp = inst["terraplan"]
        mine = makespan(inst, tp["routes"])
        row = {
            "instance": name,
            "uavs": len(inst["uavs"]),
            "jobs": len(inst["jobs"]),
            "lower_bound_s": tp["lower_bound_s"],
            "terraplan_s": mine,
            "terraplan_solve_s": tp["solve_s"],
            "ortools": {},
        }
        for s in limits:
            got, took, empty = solve_ortools(inst, s)
            row["ortools"][str(s)] = {"makespan_s": got, "solve_s": took, "idle_uavs": empty}
        if args.pyvrp_s > 0:
            got, took, empty = solve_pyvrp(inst, args.pyvrp_s)
            row["pyvrp"] = {"makespan_s": got, "solve_s": took, "idle_uavs": empty}
        rows.append(row)
        cells = [name, row["uavs"], row["jobs"], f"{tp['lower_bound_s']:.1f}", f"{mine:.1f}"]
        cells.append(f"{1000 * tp['solve_s']:.1f}")
        cells += [fmt(row["ortools"][str(s)]) for s in limits]
        if args.pyvrp_s > 0:
            cells += [fmt(row["pyvrp"]), f"{row['pyvrp']['solve_s']:.0f}"]
        print(
            " ".join(
                str(c).rjust(w) if i else str(c).ljust(w)
                for i, (c, w) in enumerate(zip(cells, widths))
            ),
            flush=True,
        )

    print("* the solver left a UAV without work (terraplan gives every UAV some)\n")
    summary = {"instances": len(rows)}
    for s in limits:
        pairs = [(r["terraplan_s"], r["ortools"][str(s)]["makespan_s"]) for r in rows]
        pairs = [(a, b) for a, b in pairs if b is not None]
        ratios = [a / b for a, b in pairs]
        wins = sum(a <= b * (1 + 1e-9) for a, b in pairs)
        time_ratio = [r["terraplan_solve_s"] / r["ortools"][str(s)]["solve_s"] for r in rows]
        summary[f"ortools_{s}s"] = {
            "terraplan_at_or_below": wins,
            "worst_ratio": max(ratios),
            "mean_ratio": statistics.fmean(ratios),
            "max_time_ratio": max(time_ratio),
        }
        print(
            f"vs OR-tools {s:>2} s: terraplan <= OR-tools on {wins} of {len(pairs)}; "
            f"makespan ratio worst {max(ratios):.4f}, mean {statistics.fmean(ratios):.4f}; "
            f"terraplan's time at most {100 * max(time_ratio):.3f} % of OR-tools'"
        )
    if args.pyvrp_s > 0:
        pairs = [(r["terraplan_s"], r["pyvrp"]["makespan_s"]) for r in rows]
        pairs = [(a, b) for a, b in pairs if b is not None]
        if pairs:
            ratios = [a / b for a, b in pairs]
            wins = sum(a <= b * (1 + 1e-9) for a, b in pairs)
            summary["pyvrp"] = {"terraplan_at_or_below": wins, "worst_ratio": max(ratios)}
            print(
                f"vs PyVRP ({args.pyvrp_s:.0f} s, bisection on a shift limit): terraplan <= "
                f"PyVRP on {wins} of {len(pairs)}; makespan ratio worst {max(ratios):.4f}"
            )
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"rows": rows, "summary": summary}, indent=1))
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
