"""A vehicle nobody here wrote: MAVSDK's MissionRawServer (the C++ library
in the `mavsdk` wheel) as an autopilot on 127.0.0.1, for `terraplan
upload`'s end-to-end test.

usage: mavsdk_vehicle.py PORT OUT_JSON [MAX_SECONDS]

Listens with MAVSDK's `udpin://127.0.0.1:PORT`, prints `READY` once the
server component is up, and writes every mission MAVSDK reports as
received (subscribe_incoming_mission) to OUT_JSON as
`{"missions": [[item, ...], ...]}` with each item's MISSION_ITEM_INT
fields (NaN params as null). Read-back requests are answered by MAVSDK
itself. Exits after MAX_SECONDS (default 60) or on SIGTERM.
"""
import json
import math
import os
import signal
import sys
import threading
import time

import mavsdk
from mavsdk.plugins.mission_raw_server import MissionRawServer


def item_json(it):
    def num(v):
        return None if isinstance(v, float) and math.isnan(v) else v
    return {
        "seq": it.seq, "frame": it.frame, "command": it.command,
        "current": it.current, "autocontinue": it.autocontinue,
        "param1": num(it.param1), "param2": num(it.param2),
        "param3": num(it.param3), "param4": num(it.param4),
        "x": it.x, "y": it.y, "z": num(it.z), "mission_type": it.mission_type,
    }


def main():
    port, out = int(sys.argv[1]), sys.argv[2]
    max_s = float(sys.argv[3]) if len(sys.argv) > 3 else 60.0
    mavsdk.log_subscribe(lambda level, _m, _f, _l: level < mavsdk.LogLevel.WARN)
    sdk = mavsdk.Mavsdk(mavsdk.Configuration.create_with_component_type(
        mavsdk.ComponentType.AUTOPILOT))
    result = sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
    if result != mavsdk.ConnectionResult.SUCCESS:
        print(f"mavsdk_vehicle: cannot listen on {port}: {result}", file=sys.stderr)
        sys.exit(1)
    server = MissionRawServer(sdk.server_component())
    missions = []
    lock = threading.Lock()

    def on_mission(res, plan, _ud):
        with lock:
            missions.append({"result": res.name,
                             "items": [item_json(i) for i in plan.mission_items]})
            with open(out + ".tmp", "w") as f:
                json.dump({"missions": missions}, f)
            # Atomic for the reader.
            os.replace(out + ".tmp", out)

    server.subscribe_incoming_mission(on_mission)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    print("READY", flush=True)
    deadline = time.time() + max_s
    while not stop.is_set() and time.time() < deadline:
        time.sleep(0.05)


if __name__ == "__main__":
    main()
