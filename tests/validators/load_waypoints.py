"""Load a QGC WPL 110 file with pymavlink's MAVWPLoader and print what it
read as JSON: item count, and per item seq, frame, command, params, lat,
lon, alt. A NaN param (the yaw "keep the heading" of take-off and
waypoints) is printed as null, since JSON has no NaN.
usage: load_waypoints.py FILE"""
import json
import math
import sys

from pymavlink import mavwp

loader = mavwp.MAVWPLoader()
n = loader.load(sys.argv[1])
items = []
for i in range(n):
    w = loader.wp(i)
    items.append({
        "seq": w.seq, "frame": w.frame, "command": w.command,
        "params": [None if math.isnan(p) else p for p in (w.param1, w.param2, w.param3, w.param4)],
        "lat": w.x, "lon": w.y, "alt": w.z,
    })
print(json.dumps({"count": n, "items": items}, allow_nan=False))
