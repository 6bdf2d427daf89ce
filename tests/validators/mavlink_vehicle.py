"""A MAVLink vehicle for `terraplan upload`'s end-to-end tests, written
with pymavlink: it keeps a mission, fence and rally list (MAVLink mission
protocol, vehicle side, with the vehicle's own re-requests), and can lose
and repeat messages (seeded), refuse an upload, or store an item other
than the one sent.

usage: mavlink_vehicle.py --port PORT --out OUT_JSON [--seed N]
         [--drop P] [--repeat P] [--nack KIND:RESULT] [--corrupt KIND:SEQ]
         [--stall KIND:SEQ] [--legacy] [--max-seconds S]

Listens on udp 127.0.0.1:PORT (port 0: any; the port is printed as
`READY <port>`), answers whoever sent last. --drop loses each incoming
and outgoing message with probability P, --repeat sends each answer twice
with probability P (random.Random(seed)). --nack answers MISSION_COUNT of
KIND (mission, fence, rally) with MISSION_ACK of RESULT (e.g.
MAV_MISSION_NO_SPACE). --corrupt adds 1 to x of item SEQ as stored.
--stall stops answering an upload of KIND when item SEQ arrives (no more
requests, no ACK: a vehicle gone quiet mid-transfer). --legacy asks for
items with MISSION_REQUEST. After each completed upload (and a stall, and a
MISSION_ACK OPERATION_CANCELLED from the ground station) OUT_JSON is
rewritten: {"mission": [items], "fence": [...], "rally": [...], "dropped":
n, "repeated": n, "stalled": bool, "cancelled_by_gcs": n} with
MISSION_ITEM_INT fields.
"""
import argparse
import json
import math
import os
import random
import sys
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

ML = mavutil.mavlink
KINDS = {"mission": ML.MAV_MISSION_TYPE_MISSION, "fence": ML.MAV_MISSION_TYPE_FENCE,
         "rally": ML.MAV_MISSION_TYPE_RALLY}
NAMES = {v: k for k, v in KINDS.items()}
# The vehicle asks again for an item this long after its last request,
# at most RE_REQUESTS times, as autopilots do.
RE_REQUEST_S = 0.4
RE_REQUESTS = 10


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--drop", type=float, default=0.0)
    ap.add_argument("--repeat", type=float, default=0.0)
    ap.add_argument("--nack")
    ap.add_argument("--corrupt")
    ap.add_argument("--stall")
    ap.add_argument("--legacy", action="store_true")
    ap.add_argument("--max-seconds", type=float, default=60.0)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    nack = None
    if a.nack:
        kind, result = a.nack.split(":")
        nack = (KINDS[kind], getattr(ML, result))
    stall = None
    if a.stall:
        kind, seq = a.stall.split(":")
        stall = (KINDS[kind], int(seq))
    corrupt = None
    if a.corrupt:
        kind, seq = a.corrupt.split(":")
        corrupt = (KINDS[kind], int(seq))

    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{a.port}", source_system=1,
                                      source_component=1)
    print(f"READY {conn.port.getsockname()[1]}", flush=True)
    lists = {t: [] for t in KINDS.values()}
    stats = {"dropped": 0, "repeated": 0, "stalled": False, "cancelled_by_gcs": 0}
    receiving = None  # [type, count, items, last_request_time, re_requests]
    completed = None  # (type, count) of the list last received in full

    def save():
        doc = {NAMES[t]: items for t, items in lists.items()}
        doc.update(stats)
        with open(a.out + ".tmp", "w") as f:
            json.dump(doc, f)
        os.replace(a.out + ".tmp", a.out)

    def send(msg):
        if rng.random() < a.drop:
            stats["dropped"] += 1
            return
        conn.mav.send(msg)
        if rng.random() < a.repeat:
            stats["repeated"] += 1
            conn.mav.send(msg)

    def ack(mission_type, result):
        send(ML.MAVLink_mission_ack_message(255, 0, result, mission_type))

    def request(mission_type, seq):
        if a.legacy:
            send(ML.MAVLink_mission_request_message(255, 0, seq, mission_type))
        else:
            send(ML.MAVLink_mission_request_int_message(255, 0, seq, mission_type))

    save()
    deadline = time.time() + a.max_seconds
    while time.time() < deadline:
        m = conn.recv_match(blocking=True, timeout=0.05)
        now = time.time()
        if receiving is not None and now - receiving[3] > RE_REQUEST_S:
            if receiving[4] >= RE_REQUESTS:
                ack(receiving[0], ML.MAV_MISSION_OPERATION_CANCELLED)
                receiving = None
            else:
                receiving[3], receiving[4] = now, receiving[4] + 1
                request(receiving[0], len(receiving[2]))
        if m is None:
            continue
        if rng.random() < a.drop:
            stats["dropped"] += 1
            continue
        t = m.get_type()
        if t == "MISSION_COUNT":
            mt = m.mission_type
            if nack is not None and nack[0] == mt:
                ack(mt, nack[1])
            elif m.count == 0:
                lists[mt] = []
                receiving = None
                ack(mt, ML.MAV_MISSION_ACCEPTED)
                save()
            else:
                receiving = [mt, m.count, [], now, 0]
                request(mt, 0)
        elif t in ("MISSION_ITEM_INT", "MISSION_ITEM") and receiving is None:
            # The last item again after the list was complete: our
            # MISSION_ACK was lost, so send it again.
            if completed == (m.mission_type, m.seq + 1):
                ack(m.mission_type, ML.MAV_MISSION_ACCEPTED)
        elif t in ("MISSION_ITEM_INT", "MISSION_ITEM"):
            mt, count, items = receiving[0], receiving[1], receiving[2]
            # An older duplicate is ignored; a repeat of the last item
            # means our request was lost, so ask again (as PX4 does).
            if m.mission_type != mt or m.seq + 1 < len(items):
                continue
            if stall == (mt, m.seq):
                # Gone quiet: this transfer is never answered again.
                receiving = None
                stats["stalled"] = True
                save()
                continue
            if m.seq == len(items):
                x, y = m.x, m.y
                if t == "MISSION_ITEM":
                    x, y = round(x * 1e7), round(y * 1e7)
                if corrupt == (mt, m.seq):
                    x += 1
                nan = lambda v: None if math.isnan(v) else v  # noqa: E731
                items.append({"seq": m.seq, "frame": m.frame, "command": m.command,
                              "current": m.current, "autocontinue": m.autocontinue,
                              "param1": nan(m.param1), "param2": nan(m.param2),
                              "param3": nan(m.param3), "param4": nan(m.param4),
                              "x": x, "y": y, "z": nan(m.z), "mission_type": mt,
                              "wire": t})
            if len(items) == count:
                completed = (mt, count)
                lists[mt] = items
                receiving = None
                ack(mt, ML.MAV_MISSION_ACCEPTED)
                save()
            else:
                receiving[3], receiving[4] = now, 0
                request(mt, len(items))
        elif t == "MISSION_ACK" and m.type == ML.MAV_MISSION_OPERATION_CANCELLED:
            # The ground station gave up a transfer (its client went away).
            receiving = None
            stats["cancelled_by_gcs"] += 1
            save()
        elif t == "MISSION_REQUEST_LIST":
            send(ML.MAVLink_mission_count_message(255, 0, len(lists[m.mission_type]),
                                                  m.mission_type))
        elif t in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            items = lists[m.mission_type]
            if m.seq >= len(items):
                ack(m.mission_type, ML.MAV_MISSION_INVALID_SEQUENCE)
                continue
            it = items[m.seq]
            f = lambda v: float("nan") if v is None else v  # noqa: E731
            send(ML.MAVLink_mission_item_int_message(
                255, 0, it["seq"], it["frame"], it["command"], 0, it["autocontinue"],
                f(it["param1"]), f(it["param2"]), f(it["param3"]), f(it["param4"]),
                it["x"], it["y"], f(it["z"]), m.mission_type))
    save()


if __name__ == "__main__":
    main()
