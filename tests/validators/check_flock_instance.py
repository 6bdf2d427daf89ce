"""Checks flock routing instances (`terraplan experiment flock --instances`)
independently of terraplan: the document's shape, and the makespan of the
plan's routes recomputed from the travel matrix and job durations alone.

Usage: check_flock_instance.py DIR   (every *.json in DIR)
Prints one JSON line per instance and exits 1 on the first fault.
The model (issue 21): a job is flown from either end to the other, every
UAV returns to its start, a UAV's time is its travel plus its jobs'
durations, the makespan is the largest.
"""

import json
import math
import pathlib
import sys

TOLERANCE_S = 1e-6


def fail(name, msg):
    print(f"{name}: {msg}", file=sys.stderr)
    sys.exit(1)


def route_time(doc, start, route):
    """Seconds a UAV starting (and ending) at node `start` needs for `route`."""
    travel = doc["travel_s"]
    at, t = start, 0.0
    for job, reversed_ in route:
        a, b = doc["jobs"][job]["ends"]
        entry, exit_ = (b, a) if reversed_ else (a, b)
        t += travel[at][entry] + doc["jobs"][job]["duration_s"]
        at = exit_
    return t + travel[at][start]


def check(path):
    doc = json.loads(path.read_text())
    name = doc.get("name", path.name)
    for key in ("name", "uavs", "jobs", "travel_s", "terraplan"):
        if key not in doc:
            fail(name, f"no {key!r}")
    travel = doc["travel_s"]
    nodes = len(travel)
    if any(len(row) != nodes for row in travel):
        fail(name, "travel_s is not square")
    if any(not math.isfinite(x) or x < 0 for row in travel for x in row):
        fail(name, "travel_s has a negative or non-finite time")
    used = []
    for u in doc["uavs"]:
        used.append(u["start"])
    for j in doc["jobs"]:
        if len(j["ends"]) != 2 or not j["duration_s"] > 0:
            fail(name, f"job {j['id']}: two ends and a positive duration expected")
        used.extend(j["ends"])
    if sorted(used) != list(range(nodes)):
        fail(name, "the UAV starts and job ends are not the matrix's nodes, each once")

    plan = doc["terraplan"]
    routes = plan["routes"]
    if len(routes) != len(doc["uavs"]):
        fail(name, "one route per UAV expected")
    flown = sorted(job for route in routes for job, _ in route)
    if flown != list(range(len(doc["jobs"]))):
        fail(name, "the routes do not fly every job exactly once")
    times = [route_time(doc, u["start"], r) for u, r in zip(doc["uavs"], routes)]
    makespan = max(times)
    if abs(makespan - plan["makespan_s"]) > TOLERANCE_S:
        fail(name, f"recomputed makespan {makespan!r} != terraplan's {plan['makespan_s']!r}")
    if abs(makespan - plan["flown_makespan_s"]) > TOLERANCE_S:
        fail(name, f"recomputed makespan {makespan!r} != flown {plan['flown_makespan_s']!r}")
    if plan["lower_bound_s"] > makespan * (1 + 1e-9):
        fail(name, f"lower bound {plan['lower_bound_s']} above the makespan {makespan}")
    if not plan["solve_s"] >= 0:
        fail(name, "solve_s missing or negative")
    return {
        "name": name,
        "uavs": len(doc["uavs"]),
        "jobs": len(doc["jobs"]),
        "makespan_s": makespan,
        "error_s": abs(makespan - plan["makespan_s"]),
    }


def main():
    files = sorted(pathlib.Path(sys.argv[1]).glob("*.json"))
    if not files:
        fail(sys.argv[1], "no instances")
    for path in files:
        print(json.dumps(check(path)))


if __name__ == "__main__":
    main()
