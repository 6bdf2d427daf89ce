"""Check terraplan's Litchi missions (`<stem>.litchi.csv`, or
`<stem>.part<k>.litchi.csv` past 99 waypoints) with Python's csv reader
against Litchi's documented CSV columns (metric variant, as Litchi Mission
Hub exports and imports them) and against the plan's own mission
(`<stem>.waypoints`, QGC WPL 110) and plan.json.

usage: check_litchi.py OUT_DIR
Prints a JSON summary; exits 1 on a fault."""
import csv
import json
import os
import re
import sys

# latitude … gimbalpitchangle, 15 action slots, altitude mode, speed, POI,
# photo intervals: Litchi's header, in its order.
COLUMNS = (["latitude", "longitude", "altitude(m)", "heading(deg)", "curvesize(m)", "rotationdir",
            "gimbalmode", "gimbalpitchangle"]
           + [c for i in range(1, 16) for c in (f"actiontype{i}", f"actionparam{i}")]
           + ["altitudemode", "speed(m/s)", "poi_latitude", "poi_longitude", "poi_altitude(m)",
              "poi_altitudemode", "photo_timeinterval", "photo_distinterval"])
MAX_ROWS = 99
# -1 none, 0 stay (ms), 1 photo, 2/3 start/stop recording, 4 rotate
# aircraft, 5 tilt camera.
ACTIONS = {-1, 0, 1, 2, 3, 4, 5}
PART = re.compile(r"^(?P<stem>.+?)(\.part(?P<k>[1-9][0-9]*))?\.litchi\.csv$")

faults = []


def read_waypoints(path):
    """(frame, lon, lat, alt) of every NAV_WAYPOINT (16) after home, and home's AMSL height."""
    rows = [line.split("\t") for line in open(path).read().splitlines()[1:] if line.strip()]
    pts = [(int(r[2]), float(r[9]), float(r[8]), float(r[10])) for r in rows[1:] if r[3] == "16"]
    return pts, float(rows[0][10])


def read_part(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    name = os.path.basename(path)
    if not rows or rows[0] != COLUMNS:
        faults.append(f"{name}: header is not Litchi's {len(COLUMNS)} columns")
        return []
    body = rows[1:]
    if not 1 <= len(body) <= MAX_ROWS:
        faults.append(f"{name}: {len(body)} waypoints, Litchi takes 1 to {MAX_ROWS}")
    out = []
    for i, r in enumerate(body):
        where = f"{name} row {i + 1}"
        if len(r) != len(COLUMNS):
            faults.append(f"{where}: {len(r)} fields")
            continue
        row = dict(zip(COLUMNS, (float(v) for v in r)))
        if not (-90 <= row["latitude"] <= 90 and -180 <= row["longitude"] <= 180):
            faults.append(f"{where}: position out of range")
        if not -200 <= row["altitude(m)"] <= 500 or row["altitudemode"] not in (0, 1):
            faults.append(f"{where}: altitude {row['altitude(m)']} (mode {row['altitudemode']})")
        if not 0 <= row["heading(deg)"] <= 360 or row["gimbalmode"] not in (0, 1, 2):
            faults.append(f"{where}: heading or gimbal mode out of range")
        if not -90 <= row["gimbalpitchangle"] <= 30 or not 0 <= row["speed(m/s)"] <= 15:
            faults.append(f"{where}: gimbal pitch or speed out of range")
        if any(row[f"actiontype{k}"] not in ACTIONS for k in range(1, 16)):
            faults.append(f"{where}: unknown action type")
        out.append(row)
    return out


def main():
    out = sys.argv[1]
    plan = json.load(open(os.path.join(out, "plan.json")))
    frame = plan["altitude_frame"]
    parts = {}
    for f in os.listdir(out):
        m = PART.match(f)
        if m:
            parts.setdefault(m["stem"], {})[int(m["k"] or 0)] = f
    if not parts:
        faults.append(f"no Litchi file in {out}")
    summary = []
    for stem, files in sorted(parts.items()):
        ks = sorted(files)
        if ks != [0] and ks != list(range(1, len(ks) + 1)):
            faults.append(f"{stem}: Litchi files numbered {ks}")
            continue
        rows = []
        for n, k in enumerate(ks):
            part = read_part(os.path.join(out, files[k]))
            # A later part starts where the one before ended.
            if n and part and rows:
                if (part[0]["latitude"], part[0]["longitude"]) != (rows[-1]["latitude"], rows[-1]["longitude"]):
                    faults.append(f"{files[k]}: does not start where the part before ended")
                part = part[1:]
            rows += part
        pts, home_amsl = read_waypoints(os.path.join(out, stem + ".waypoints"))
        if len(rows) != len(pts):
            faults.append(f"{stem}: {len(rows)} Litchi waypoints, the plan has {len(pts)}")
        max_pos = max_alt = 0.0
        for r, (f_, lon, lat, alt) in zip(rows, pts):
            max_pos = max(max_pos, abs(r["latitude"] - lat), abs(r["longitude"] - lon))
            # Above take-off (AMSL less home's height), or above ground.
            want = alt - home_amsl if frame == "amsl" else alt
            want_mode = 1 if frame == "terrain" else 0
            if r["altitudemode"] != want_mode:
                faults.append(f"{stem}: altitudemode {r['altitudemode']} in the {frame} frame")
            max_alt = max(max_alt, abs(r["altitude(m)"] - want))
        if max_pos > 1e-7:
            faults.append(f"{stem}: a waypoint lies {max_pos:.2e}° from the plan's")
        if max_alt > 1e-3:
            faults.append(f"{stem}: an altitude differs from the plan's by {max_alt:.4f} m")
        photos_here = sum(1 for r in rows for k in range(1, 16) if r[f"actiontype{k}"] == 1)
        summary.append({"stem": stem, "files": len(ks), "waypoints": len(rows),
                        "max_position_diff_deg": max_pos, "max_altitude_diff_m": max_alt,
                        "photo_actions": photos_here,
                        "rows_photographed": sum(1 for r in rows if r["photo_distinterval"] > 0
                                                 or r["photo_timeinterval"] > 0)})
    print(json.dumps({"missions": summary, "faults": faults}, indent=1))
    sys.exit(1 if faults else 0)


if __name__ == "__main__":
    main()
