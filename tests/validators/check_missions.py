"""The same mission in every format, read by other people's loaders.

For every `<stem>.plan` in a survey output directory, with its
`<stem>.waypoints`, its UAV's `<uav>.fence.waypoints` and (when the plan
has rally points) `<uav>.rally.waypoints`:

- pymavlink reads the WPL files and json the `.plan`; they agree item by
  item (command, frame, params 1-4 with yaw, position), take-off and
  waypoint yaw is NaN ("keep the heading") in both, the `.plan` fence
  polygons carry the keys QGroundControl's loader requires (version,
  inclusion, fenceAction, polygon) and equal the fence file's items, and
  the `.plan` rally points equal the rally file's;
- MAVSDK (the `mavsdk` package; a HEARTBEAT of an ArduPilot quadrotor fed
  through a `raw://` connection stands in for the vehicle) imports the
  `.plan` with `import_qgroundcontrol_mission` and the `.waypoints` with
  `import_mission_planner_mission`, and gets the same items;
- MAVProxy (`mavproxy.py --cmd "wp load …; fence load …; rally load …"`)
  loads the three files and uploads them to a stand-in vehicle played
  here over UDP on 127.0.0.1, which receives the same items.

usage: check_missions.py OUT_DIR
Prints a JSON summary; exits 1 with a message on the first failed check.
"""
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil, mavwp  # noqa: E402

import mavsdk  # noqa: E402
from mavsdk.plugins.mission_raw import MissionRaw  # noqa: E402

ML = mavutil.mavlink
KEEP_HEADING_COMMANDS = (ML.MAV_CMD_NAV_WAYPOINT, ML.MAV_CMD_NAV_TAKEOFF)
# Frames whose x/y are degrees (MAVSDK and MAVProxy send them as degE7).
GLOBAL_FRAMES = (0, 3, 5, 6, 10, 11)
# Tolerances: .waypoints prints params and altitudes with 6 decimals,
# lat/lon with 8; MAVLink items carry params and z as float32 and lat/lon
# as integer degE7 (MAVProxy truncates, MAVSDK rounds).
PARAM_TOL = 5e-7
LATLON_TOL = 1e-8
ALT_TOL = 1e-6
DEGE7_TOL = 1
MAVPROXY_TIMEOUT_S = 30.0


def fail(msg):
    print(f"check_missions: FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


def same(a, b, tol):
    """Equal within tol, NaN equal to NaN only."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return abs(a - b) <= tol * max(1.0, abs(a), abs(b))


def f32_tol(v):
    """Float32 rounding of v, plus the 6-decimal rounding of the file."""
    return 2.0 ** -23 * max(1.0, abs(v)) + PARAM_TOL


def wpl_rows(path, loader_class):
    """Items of a QGC WPL 110 file as pymavlink reads them."""
    loader = loader_class()
    n = loader.load(str(path))
    if n is None:
        n = loader.count()
    rows = []
    for i in range(n):
        w = loader.wp(i)
        rows.append({
            "seq": w.seq, "frame": w.frame, "command": w.command,
            "params": [w.param1, w.param2, w.param3, w.param4],
            "lat": w.x, "lon": w.y, "alt": w.z,
        })
    return rows


def plan_param(v):
    # QGroundControl writes NaN as null.
    return math.nan if v is None else float(v)


def check_plan_vs_waypoints(stem, plan, rows):
    mission = plan["mission"]
    if plan.get("fileType") != "Plan" or plan.get("version") != 1 or mission.get("version") != 2:
        fail(f"{stem}.plan: not a version 1 Plan with a version 2 mission")
    home = mission["plannedHomePosition"]
    h = rows[0]
    if h["command"] != ML.MAV_CMD_NAV_WAYPOINT or h["frame"] != 0:
        fail(f"{stem}.waypoints: item 0 is not home (command 16, frame 0)")
    if not (same(h["lat"], home[0], LATLON_TOL) and same(h["lon"], home[1], LATLON_TOL)
            and same(h["alt"], home[2], ALT_TOL)):
        fail(f"{stem}: home {h} differs from plannedHomePosition {home}")
    items = mission["items"]
    if len(items) != len(rows) - 1:
        fail(f"{stem}: {len(items)} .plan items, {len(rows) - 1} .waypoints items after home")
    for k, (item, row) in enumerate(zip(items, rows[1:]), start=1):
        if item.get("type") != "SimpleItem":
            fail(f"{stem}.plan item {k}: type {item.get('type')!r}, not SimpleItem")
        if (item["command"], item["frame"]) != (row["command"], row["frame"]):
            fail(f"{stem} item {k}: command/frame {item['command']}/{item['frame']} in .plan, "
                 f"{row['command']}/{row['frame']} in .waypoints")
        params = [plan_param(v) for v in item["params"]]
        for i in range(4):
            if not same(params[i], row["params"][i], PARAM_TOL):
                fail(f"{stem} item {k} (command {row['command']}): param{i + 1} "
                     f"{params[i]} in .plan, {row['params'][i]} in .waypoints")
        if not (same(params[4], row["lat"], LATLON_TOL) and same(params[5], row["lon"], LATLON_TOL)
                and same(params[6], row["alt"], ALT_TOL)):
            fail(f"{stem} item {k}: position {params[4:]} in .plan, "
                 f"{[row['lat'], row['lon'], row['alt']]} in .waypoints")
        if row["command"] in KEEP_HEADING_COMMANDS and not math.isnan(row["params"][3]):
            fail(f"{stem} item {k}: yaw {row['params'][3]}, not NaN (keep the heading)")
    return len(items)


def check_fence(stem, plan, fence_rows):
    fence = plan["geoFence"]
    if fence.get("version") != 2 or not isinstance(fence.get("circles"), list):
        fail(f"{stem}.plan: geoFence is not version 2 with circles and polygons")
    expected = []
    for j, poly in enumerate(fence["polygons"]):
        # QGCFencePolygon::loadFromJson requires these keys and types.
        if poly.get("version") != 1 or not isinstance(poly.get("inclusion"), bool) \
                or not isinstance(poly.get("fenceAction"), (int, float)) \
                or isinstance(poly.get("fenceAction"), bool):
            fail(f"{stem}.plan fence polygon {j}: needs version 1, inclusion (bool) and fenceAction (number)")
        vertices = poly["polygon"]
        if len(vertices) < 3 or any(len(v) != 2 for v in vertices):
            fail(f"{stem}.plan fence polygon {j}: needs 3 or more [lat, lon] vertices")
        command = (ML.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION if poly["inclusion"]
                   else ML.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
        for lat, lon in vertices:
            expected.append((command, len(vertices), poly["fenceAction"], lat, lon))
    if len(expected) != len(fence_rows):
        fail(f"{stem}: {len(expected)} fence vertices in .plan, {len(fence_rows)} in the fence file")
    for k, ((command, count, action, lat, lon), row) in enumerate(zip(expected, fence_rows)):
        if (row["command"], row["frame"]) != (command, 0) or row["params"][0] != count \
                or row["params"][2] != action \
                or not (same(row["lat"], lat, LATLON_TOL) and same(row["lon"], lon, LATLON_TOL)):
            fail(f"{stem}: fence item {k} {row} differs from the .plan's "
                 f"{(command, count, action, lat, lon)}")
    return expected


def check_rally(stem, plan, rally_rows):
    rally = plan["rallyPoints"]
    if rally.get("version") != 2:
        fail(f"{stem}.plan: rallyPoints is not version 2")
    points = rally["points"]
    if len(points) != len(rally_rows):
        fail(f"{stem}: {len(points)} rally points in .plan, {len(rally_rows)} in the rally file")
    for k, (p, row) in enumerate(zip(points, rally_rows)):
        if len(p) != 3:
            fail(f"{stem}.plan rally point {k}: not [lat, lon, alt]")
        if (row["command"], row["frame"]) != (ML.MAV_CMD_NAV_RALLY_POINT, ML.MAV_FRAME_GLOBAL_RELATIVE_ALT) \
                or not (same(row["lat"], p[0], LATLON_TOL) and same(row["lon"], p[1], LATLON_TOL)
                        and same(row["alt"], p[2], ALT_TOL)):
            fail(f"{stem}: rally item {k} {row} differs from the .plan's {p}")


def check_item(where, got, row, position=True):
    """A MAVLink MISSION_ITEM_INT (from MAVSDK or MAVProxy) against a file row."""
    if (got.command, got.frame) != (row["command"], row["frame"]):
        fail(f"{where}: command/frame {got.command}/{got.frame}, file has {row['command']}/{row['frame']}")
    for i, name in enumerate(("param1", "param2", "param3", "param4")):
        v = getattr(got, name)
        if not same(v, row["params"][i], f32_tol(row["params"][i])):
            fail(f"{where}: {name} {v}, file has {row['params'][i]}")
    if position and row["frame"] in GLOBAL_FRAMES:
        x, y = row["lat"] * 1e7, row["lon"] * 1e7
        if abs(got.x - x) > DEGE7_TOL or abs(got.y - y) > DEGE7_TOL:
            fail(f"{where}: position {got.x}, {got.y} (degE7), file has {row['lat']}, {row['lon']}")
    if not same(got.z, row["alt"], f32_tol(row["alt"])):
        fail(f"{where}: altitude {got.z}, file has {row['alt']}")


class Mavsdk:
    """MAVSDK with an ArduPilot quadrotor announced by one HEARTBEAT."""

    def __init__(self):
        # MAVSDK's warnings and errors go to stderr; its info does not.
        mavsdk.log_subscribe(lambda level, _msg, _file, _line: level < mavsdk.LogLevel.WARN)
        self.sdk = mavsdk.Mavsdk(mavsdk.Configuration.create_with_component_type(
            mavsdk.ComponentType.GROUND_STATION))
        if self.sdk.add_any_connection("raw://") != mavsdk.ConnectionResult.SUCCESS:
            fail("MAVSDK: no raw:// connection")
        # What MAVSDK would send to the vehicle goes nowhere.
        self.sub = self.sdk.subscribe_raw_bytes_to_be_sent(lambda _data: None)
        mav = mavutil.mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        hb = mav.heartbeat_encode(ML.MAV_TYPE_QUADROTOR, ML.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, ML.MAV_STATE_STANDBY)
        deadline = time.time() + 10.0
        system = None
        while system is None and time.time() < deadline:
            self.sdk.pass_received_raw_bytes(bytes(hb.pack(mav)))
            system = self.sdk.first_autopilot(0.2)
        if system is None:
            fail("MAVSDK saw no autopilot after its HEARTBEAT")
        self.system = system
        self.raw = MissionRaw(system)

    def check(self, stem, plan_path, wp_path, rows, fence_rows, rally_rows):
        data = self.raw.import_qgroundcontrol_mission(str(plan_path))
        # For ArduPilot MAVSDK puts plannedHomePosition first.
        items = data.mission_items
        if len(items) != len(rows):
            fail(f"MAVSDK {stem}.plan: {len(items)} mission items, the .waypoints has {len(rows)}")
        home = rows[0]
        check_item(f"MAVSDK {stem}.plan home", items[0], {**home, "frame": 5})
        for k, (got, row) in enumerate(zip(items[1:], rows[1:]), start=1):
            check_item(f"MAVSDK {stem}.plan item {k}", got, row)
        for name, got_items, want in (("fence", data.geofence_items, fence_rows),
                                      ("rally", data.rally_items, rally_rows)):
            if len(got_items) != len(want):
                fail(f"MAVSDK {stem}.plan: {len(got_items)} {name} items, the {name} file has {len(want)}")
            for k, (got, row) in enumerate(zip(got_items, want)):
                check_item(f"MAVSDK {stem}.plan {name} item {k}", got, row)
        # The Mission Planner importer (QGC WPL 110). For ArduPilot it puts
        # a copy of the first row before the file's rows, and it scales x/y
        # to degE7 only in frames 0, 3, 5 and 6.
        mp = self.raw.import_mission_planner_mission(str(wp_path)).mission_items
        if len(mp) != len(rows) + 1:
            fail(f"MAVSDK {stem}.waypoints: {len(mp)} items, expected {len(rows) + 1}")
        for k, (got, row) in enumerate(zip(mp[1:], rows)):
            check_item(f"MAVSDK {stem}.waypoints item {k}", got, row,
                       position=row["frame"] in (0, 3, 5, 6))
        return {"mission": len(items), "fence": len(data.geofence_items), "rally": len(data.rally_items)}


def free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def mavproxy_upload(files):
    """MAVProxy loads `files` ({mission_type: path}) and uploads them to a
    stand-in vehicle (system 1) listening on a free UDP port of 127.0.0.1;
    returns the items the vehicle received, by mission type."""
    port = free_udp_port()
    vehicle = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=1,
                                         source_component=1, dialect="common")
    verbs = {ML.MAV_MISSION_TYPE_MISSION: "wp", ML.MAV_MISSION_TYPE_FENCE: "fence",
             ML.MAV_MISSION_TYPE_RALLY: "rally"}
    cmds = "; ".join(f'{verbs[t]} load {p}' for t, p in files.items())
    script = Path(sys.executable).parent / "mavproxy.py"
    # --target-system: the files load for system 1 before its first HEARTBEAT.
    argv = [sys.executable, str(script), f"--master=udpout:127.0.0.1:{port}", "--no-state",
            "--non-interactive", "--target-system=1", "--target-component=1",
            f"--default-modules={','.join(verbs[t] for t in files)}", f"--cmd={cmds}"]
    with tempfile.TemporaryDirectory() as cwd:
        proc = subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)
        expected, got, asked, peer = {}, {}, {}, {}
        deadline = time.time() + MAVPROXY_TIMEOUT_S
        last_hb = 0.0
        def complete():
            return all(t in got and len(got[t]) >= expected[t] for t in files)

        try:
            while not complete() and time.time() < deadline:
                now = time.time()
                if now - last_hb > 0.5:
                    vehicle.mav.heartbeat_send(ML.MAV_TYPE_QUADROTOR, ML.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0,
                                               ML.MAV_STATE_STANDBY)
                    last_hb = now
                # A real autopilot asks again for an item that did not come.
                for t, when in list(asked.items()):
                    if len(got[t]) < expected[t] and now - when > 0.5:
                        vehicle.mav.mission_request_int_send(*peer[t], len(got[t]), t)
                        asked[t] = now
                m = vehicle.recv_match(blocking=True, timeout=0.1)
                if m is None:
                    continue
                kind = m.get_type()
                if kind == "MISSION_COUNT" and m.mission_type in files:
                    t = m.mission_type
                    expected[t], got[t] = m.count, []
                    peer[t] = (m.get_srcSystem(), m.get_srcComponent())
                    vehicle.mav.mission_request_int_send(*peer[t], 0, t)
                    asked[t] = time.time()
                elif kind in ("MISSION_ITEM_INT", "MISSION_ITEM") and m.mission_type in got:
                    t = m.mission_type
                    if m.seq == len(got[t]):
                        got[t].append(m)
                        if len(got[t]) < expected[t]:
                            vehicle.mav.mission_request_int_send(*peer[t], len(got[t]), t)
                            asked[t] = time.time()
                        else:
                            vehicle.mav.mission_ack_send(*peer[t], ML.MAV_MISSION_ACCEPTED, t)
        finally:
            proc.terminate()
            try:
                out = proc.communicate(timeout=10)[0]
            except subprocess.TimeoutExpired:
                proc.kill()
                out = proc.communicate()[0]
            vehicle.close()
    for t, path in files.items():
        if t not in got or len(got[t]) < expected[t]:
            fail(f"MAVProxy did not upload {path} within {MAVPROXY_TIMEOUT_S} s; it said:\n{out}")
    return got


def main():
    out = Path(sys.argv[1])
    plans = sorted(out.glob("*.plan"))
    if not plans:
        fail(f"{out}: no .plan files")
    sdk = Mavsdk()
    summary = {"stems": {}}
    for plan_path in plans:
        stem = plan_path.name[: -len(".plan")]
        uav = stem.split(".")[0]
        wp_path = out / f"{stem}.waypoints"
        fence_path = out / f"{uav}.fence.waypoints"
        rally_path = out / f"{uav}.rally.waypoints"
        for p in (wp_path, fence_path):
            if not p.exists():
                fail(f"{p} is missing beside {plan_path.name}")
        plan = json.loads(plan_path.read_text())
        rows = wpl_rows(wp_path, mavwp.MAVWPLoader)
        items = check_plan_vs_waypoints(stem, plan, rows)
        fence_rows = wpl_rows(fence_path, mavwp.MissionItemProtocol_Fence)
        check_fence(stem, plan, fence_rows)
        has_rally = bool(plan["rallyPoints"]["points"])
        if has_rally != rally_path.exists():
            fail(f"{stem}.plan has {len(plan['rallyPoints']['points'])} rally points; "
                 f"{rally_path.name} {'is missing' if has_rally else 'exists'}")
        rally_rows = wpl_rows(rally_path, mavwp.MissionItemProtocol_Rally) if has_rally else []
        check_rally(stem, plan, rally_rows)

        imported = sdk.check(stem, plan_path, wp_path, rows, fence_rows, rally_rows)

        files = {ML.MAV_MISSION_TYPE_MISSION: wp_path, ML.MAV_MISSION_TYPE_FENCE: fence_path}
        if has_rally:
            files[ML.MAV_MISSION_TYPE_RALLY] = rally_path
        t0 = time.time()
        uploaded = mavproxy_upload(files)
        want = {ML.MAV_MISSION_TYPE_MISSION: rows, ML.MAV_MISSION_TYPE_FENCE: fence_rows,
                ML.MAV_MISSION_TYPE_RALLY: rally_rows}
        for t, got in uploaded.items():
            if len(got) != len(want[t]):
                fail(f"MAVProxy uploaded {len(got)} items of {files[t].name}, the file has {len(want[t])}")
            for k, (m, row) in enumerate(zip(got, want[t])):
                check_item(f"MAVProxy {files[t].name} item {k}", m, row)
        summary["stems"][stem] = {
            "items": items, "fence_items": len(fence_rows), "rally_items": len(rally_rows),
            "mavsdk": imported, "mavproxy_upload_s": round(time.time() - t0, 2),
        }
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
