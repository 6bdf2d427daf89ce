"""Check terraplan's DJI WPML missions (`<stem>.kmz`) against DJI's public
WPML reference (developer.dji.com, Cloud API > DJI WPML: overview,
template.kml, waylines.wpml, common elements, product support) and against
the plan's own mission (`<stem>.waypoints`, QGC WPL 110) and plan.json.

Nothing of terraplan's is used: the KMZ is opened with zipfile, its XML
parsed with xml.etree, the .waypoints read as text, the EGM96 geoid taken
from PROJ with Debian's EGM96 grid (egm96_proj.py) and the UTM lengths of
the photo runs from GDAL's osr. Run it with Debian's Python (python3-gdal).

usage: check_wpml.py OUT_DIR
Checks every *.kmz in OUT_DIR; prints a JSON summary; exits 1 on a fault."""
import json
import math
import os
import sys
import xml.etree.ElementTree as ET
import zipfile

from osgeo import osr

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from egm96_proj import undulation_function  # noqa: E402


from photo_rule import photo_count  # noqa: E402

KML = "http://www.opengis.net/kml/2.2"
WPML = "http://www.dji.com/wpmz/1.0.2"
FILES = ["wpmz/template.kml", "wpmz/waylines.wpml"]

# Product support page: drone type/sub type and payload type (gimbal 0).
AIRCRAFT = {
    "m3e": (77, 0, 66), "m3t": (77, 1, 67), "m3ta": (77, 3, 129),
    "m30": (67, 0, 52), "m30t": (67, 1, 53), "m3d": (91, 0, 80), "m3td": (91, 1, 81),
    "m4e": (99, 0, 88), "m4t": (99, 1, 89), "m4d": (100, 0, 98), "m4td": (100, 1, 99),
}
for drone, dtype in (("m300", 60), ("m350", 89)):
    for cam, ptype in (("h20", 42), ("h20t", 43), ("h20n", 61), ("h30", 82), ("h30t", 83)):
        AIRCRAFT[f"{drone}_{cam}"] = (dtype, 0, ptype)
# takePhoto's payloadLensIndex is required on these (common elements).
LENS_REQUIRED = {67, 91, 99, 100}

ENUMS = {
    "flyToWaylineMode": {"safely", "pointToPoint"},
    "finishAction": {"goHome", "noAction", "autoLand", "gotoFirstWaypoint"},
    "exitOnRCLost": {"goContinue", "executeLostAction"},
    "executeRCLostAction": {"goBack", "landing", "hover"},
    "executeHeightMode": {"WGS84", "relativeToStartPoint", "realTimeFollowSurface"},
    "heightMode": {"EGM96", "relativeToStartPoint", "aboveGroundLevel", "realTimeFollowSurface"},
    "templateType": {"waypoint", "mapping2d", "mapping3d", "mappingStrip"},
    "waypointHeadingMode": {"followWayline", "manually", "fixed", "smoothTransition", "towardPOI"},
    "waypointTurnMode": {"coordinateTurn", "toPointAndStopWithDiscontinuityCurvature",
                         "toPointAndStopWithContinuityCurvature",
                         "toPointAndPassWithContinuityCurvature"},
    "actionGroupMode": {"sequence"},
    "actionTriggerType": {"reachPoint", "betweenAdjacentPoints", "multipleTiming", "multipleDistance"},
    "actionActuatorFunc": {"takePhoto", "startRecord", "stopRecord", "focus", "zoom", "customDirName",
                           "gimbalRotate", "rotateYaw", "hover", "gimbalEvenlyRotate",
                           "accurateShoot", "orientedShoot", "panoShot", "recordPointCloud"},
}
# Parameters each action requires (common elements, actionActuatorFuncParam).
ACTION_PARAMS = {
    "takePhoto": ["payloadPositionIndex", "fileSuffix", "useGlobalPayloadLensIndex"],
    "gimbalRotate": ["payloadPositionIndex", "gimbalHeadingYawBase", "gimbalRotateMode",
                     "gimbalPitchRotateEnable", "gimbalPitchRotateAngle", "gimbalRollRotateEnable",
                     "gimbalRollRotateAngle", "gimbalYawRotateEnable", "gimbalYawRotateAngle",
                     "gimbalRotateTimeEnable", "gimbalRotateTime"],
    "hover": ["hoverTime"],
}

faults = []


def fault(msg):
    faults.append(msg)


def w(tag):
    return f"{{{WPML}}}{tag}"


def k(tag):
    return f"{{{KML}}}{tag}"


def need(parent, tag, where, ns=WPML):
    """The text of required child `tag` (wpml: unless ns is KML)."""
    el = parent.find(f"{{{ns}}}{tag}")
    if el is None or el.text is None or not el.text.strip():
        fault(f"{where}: required <{tag}> missing")
        return None
    v = el.text.strip()
    if tag in ENUMS and v not in ENUMS[tag]:
        fault(f"{where}: <{tag}> {v!r} is not one of DJI's values")
    return v


def num(v, where):
    try:
        return float(v)
    except (TypeError, ValueError):
        fault(f"{where}: {v!r} is no number")
        return math.nan


def check_mission_config(doc, where, aircraft):
    mc = doc.find(w("missionConfig"))
    if mc is None:
        fault(f"{where}: <wpml:missionConfig> missing")
        return {}
    out = {t: need(mc, t, where) for t in (
        "flyToWaylineMode", "finishAction", "exitOnRCLost", "takeOffSecurityHeight",
        "globalTransitionalSpeed", "globalRTHHeight")}
    if out["exitOnRCLost"] == "executeLostAction":
        out["executeRCLostAction"] = need(mc, "executeRCLostAction", where)
    if not 1.2 <= num(out["takeOffSecurityHeight"], where) <= 1500:
        fault(f"{where}: takeOffSecurityHeight outside [1.2, 1500]")
    if not 1 <= num(out["globalTransitionalSpeed"], where) <= 15:
        fault(f"{where}: globalTransitionalSpeed outside [1, 15]")
    if not 2 <= num(out["globalRTHHeight"], where) <= 1500:
        fault(f"{where}: globalRTHHeight outside [2, 1500]")
    drone, payload = mc.find(w("droneInfo")), mc.find(w("payloadInfo"))
    if drone is None or payload is None:
        fault(f"{where}: droneInfo or payloadInfo missing")
        return out
    got = (int(need(drone, "droneEnumValue", where) or -1),
           int(need(drone, "droneSubEnumValue", where) or -1),
           int(need(payload, "payloadEnumValue", where) or -1))
    need(payload, "payloadPositionIndex", where)
    if got != AIRCRAFT[aircraft]:
        fault(f"{where}: drone/payload enums {got}, DJI's for {aircraft} are {AIRCRAFT[aircraft]}")
    out["drone"] = got[0]
    return out


def check_groups(pm, where, index, drone, seen_ids):
    """The action groups of a placemark: (start, end, trigger, param,
    takePhoto count) each."""
    groups = []
    for g in pm.findall(w("actionGroup")):
        gw = f"{where} action group"
        gid = int(need(g, "actionGroupId", gw) or -1)
        if gid in seen_ids:
            fault(f"{gw} {gid}: id used twice in the file")
        seen_ids.add(gid)
        start = int(need(g, "actionGroupStartIndex", gw) or -1)
        end = int(need(g, "actionGroupEndIndex", gw) or -1)
        need(g, "actionGroupMode", gw)
        if start != index or end < start:
            fault(f"{gw} {gid}: start {start}, end {end} at waypoint {index}")
        trig = g.find(w("actionTrigger"))
        ttype = need(trig, "actionTriggerType", gw) if trig is not None else None
        param = None
        if ttype in ("multipleTiming", "multipleDistance"):
            param = num(need(trig, "actionTriggerParam", gw), gw)
            if not param > 0:
                fault(f"{gw} {gid}: actionTriggerParam {param} not > 0")
        photos = 0
        for i, a in enumerate(g.findall(w("action"))):
            if need(a, "actionId", gw) != str(i):
                fault(f"{gw} {gid}: action ids not 0, 1, …")
            func = need(a, "actionActuatorFunc", gw)
            params = a.find(w("actionActuatorFuncParam"))
            if params is None:
                fault(f"{gw} {gid}: {func} without actionActuatorFuncParam")
                continue
            required = list(ACTION_PARAMS.get(func, []))
            if func == "takePhoto" and drone in LENS_REQUIRED:
                required.append("payloadLensIndex")
            for t in required:
                need(params, t, f"{gw} {gid} {func}")
            photos += func == "takePhoto"
        groups.append((start, end, ttype, param, photos))
    return groups


def read_waypoints(path):
    """(frame, lon, lat, alt) of every NAV_WAYPOINT (16) after home, and home."""
    rows = [line.split("\t") for line in open(path).read().splitlines()[1:] if line.strip()]
    home = rows[0]
    pts = [(int(r[2]), float(r[9]), float(r[8]), float(r[10])) for r in rows[1:] if r[3] == "16"]
    return pts, (float(home[9]), float(home[8]), float(home[10]))


def utm_length(transform, pts):
    xy = [transform.TransformPoint(lon, lat)[:2] for lon, lat in pts]
    return sum(math.dist(a, b) for a, b in zip(xy, xy[1:]))


def check_kmz(path, plan, sortie, geoid, transform):
    where = os.path.basename(path)
    with zipfile.ZipFile(path) as z:
        bad = z.testzip()
        if bad:
            fault(f"{where}: {bad} corrupt")
        if sorted(z.namelist()) != FILES:
            fault(f"{where}: holds {z.namelist()}, not {FILES}")
            return None
        texts = {n: z.read(n).decode("utf-8") for n in FILES}
    aircraft = plan.get("dji_aircraft", "m3e")
    docs = {}
    for n, t in texts.items():
        if f'xmlns:wpml="{WPML}"' not in t or f'xmlns="{KML}"' not in t:
            fault(f"{where}/{n}: KML and WPML {WPML} namespaces not declared")
        root = ET.fromstring(t.encode("utf-8"))  # raises on malformed XML
        if root.tag != k("kml") or root.find(k("Document")) is None:
            fault(f"{where}/{n}: no <kml><Document>")
            return None
        docs[n] = root.find(k("Document"))
    stem = where[: -len(".kmz")]
    pts, home = read_waypoints(os.path.join(os.path.dirname(path), stem + ".waypoints"))
    summary = {"file": where, "waypoints": len(pts)}
    for n, doc in docs.items():
        fw = f"{where}/{n}"
        mc = check_mission_config(doc, fw, aircraft)
        folder = doc.find(k("Folder"))
        need(folder, "templateId", fw)
        need(folder, "autoFlightSpeed", fw)
        if n.endswith("waylines.wpml"):
            need(folder, "waylineId", fw)
            summary["rth_height_m"] = num(mc.get("globalRTHHeight"), fw)
            summary["finish_action"] = mc.get("finishAction")
            summary.update(check_waylines(folder, fw, pts, mc.get("drone"), geoid, transform, sortie))
        else:
            check_template(folder, fw, len(pts))
    return summary


def check_template(folder, fw, count):
    if need(folder, "templateType", fw) == "waypoint":
        for t in ("globalWaypointTurnMode", "gimbalPitchMode", "globalHeight"):
            need(folder, t, fw)
    csp = folder.find(w("waylineCoordinateSysParam"))
    if csp is None:
        fault(f"{fw}: waylineCoordinateSysParam missing")
    else:
        if need(csp, "coordinateMode", fw) != "WGS84":
            fault(f"{fw}: coordinateMode is not WGS84")
        need(csp, "heightMode", fw)
    pitch_per_point = (folder.findtext(w("gimbalPitchMode")) or "") == "usePointSetting"
    placemarks = folder.findall(k("Placemark"))
    if len(placemarks) != count:
        fault(f"{fw}: {len(placemarks)} placemarks, the plan has {count} waypoints")
    for i, pm in enumerate(placemarks):
        pw = f"{fw} placemark {i}"
        need(pm.find(k("Point")) if pm.find(k("Point")) is not None else pm, "coordinates", pw, KML)
        if need(pm, "index", pw) != str(i):
            fault(f"{pw}: index is not {i}")
        for flag, deps in (("useGlobalHeight", ["ellipsoidHeight", "height"]),
                           ("useGlobalSpeed", ["waypointSpeed"]),
                           ("useGlobalHeadingParam", ["waypointHeadingParam"]),
                           ("useGlobalTurnParam", ["waypointTurnParam"])):
            if need(pm, flag, pw) == "0":
                for d in deps:
                    if pm.find(w(d)) is None:
                        fault(f"{pw}: {flag} 0 without {d}")
        if pitch_per_point:
            need(pm, "gimbalPitchAngle", pw)


def check_waylines(folder, fw, pts, drone, geoid, transform, sortie):
    mode = need(folder, "executeHeightMode", fw)
    want_mode = {3: "relativeToStartPoint", 0: "WGS84", 10: "realTimeFollowSurface"}[pts[0][0]]
    if mode != want_mode:
        fault(f"{fw}: executeHeightMode {mode}, the plan's frame {pts[0][0]} is {want_mode}")
    placemarks = folder.findall(k("Placemark"))
    if len(placemarks) != len(pts):
        fault(f"{fw}: {len(placemarks)} waypoints, the plan has {len(pts)}")
    max_pos, max_h = 0.0, 0.0
    speeds, groups, ids = [], [], set()
    for i, (pm, (frame, lon, lat, alt)) in enumerate(zip(placemarks, pts)):
        pw = f"{fw} waypoint {i}"
        point = pm.find(k("Point"))
        coords = need(point, "coordinates", pw, KML) if point is not None else None
        if coords is None:
            fault(f"{pw}: no Point")
            continue
        x, y = (float(c) for c in coords.split(",")[:2])
        max_pos = max(max_pos, abs(x - lon), abs(y - lat))
        if need(pm, "index", pw) != str(i):
            fault(f"{pw}: index is not {i}")
        h = num(need(pm, "executeHeight", pw), pw)
        # WGS84 mode: above the ellipsoid, the plan's AMSL plus the geoid.
        want = alt + geoid(lon, lat) if frame == 0 else alt
        max_h = max(max_h, abs(h - want))
        speed = num(need(pm, "waypointSpeed", pw), pw)
        if not 1 <= speed <= 15:
            fault(f"{pw}: waypointSpeed {speed} outside [1, 15]")
        speeds.append(speed)
        hp, tp = pm.find(w("waypointHeadingParam")), pm.find(w("waypointTurnParam"))
        if hp is None or tp is None:
            fault(f"{pw}: waypointHeadingParam or waypointTurnParam missing")
        else:
            if need(hp, "waypointHeadingMode", pw) == "smoothTransition":
                need(hp, "waypointHeadingAngle", pw)
            if need(tp, "waypointTurnMode", pw) == "coordinateTurn":
                need(tp, "waypointTurnDampingDist", pw)
        groups += check_groups(pm, pw, i, drone, ids)
    if max_pos > 1e-7:
        fault(f"{fw}: a waypoint lies {max_pos:.2e}° from the plan's")
    tol = 0.5 if pts and pts[0][0] == 0 else 1e-3
    if max_h > tol:
        fault(f"{fw}: a height differs from the plan's by {max_h:.3f} m (tolerance {tol} m)")
    photos = 0
    for start, end, ttype, param, n in groups:
        if ttype == "reachPoint":
            photos += n
        elif ttype in ("multipleDistance", "multipleTiming") and n:
            length = utm_length(transform, [(p[1], p[2]) for p in pts[start:end + 1]])
            spacing = param if ttype == "multipleDistance" else param * speeds[start]
            photos += n * photo_count(length, spacing)
    want_photos = sortie["stats"]["photos"]
    if photos != want_photos:
        fault(f"{fw}: the photo actions take {photos} photos, the plan {want_photos}")
    return {"execute_height_mode": mode, "photos": photos, "plan_photos": want_photos,
            "max_position_diff_deg": max_pos, "max_height_diff_m": max_h,
            "action_groups": len(groups)}


def main():
    out = sys.argv[1]
    plan = json.load(open(os.path.join(out, "plan.json")))
    sorties = {s["file_stem"]: s for u in plan["uavs"] for s in u["sorties"]}
    geoid = undulation_function()
    wgs84 = osr.SpatialReference()
    wgs84.ImportFromEPSG(4326)
    wgs84.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
    utm = osr.SpatialReference()
    utm.ImportFromEPSG(plan["utm_epsg"])
    utm.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
    transform = osr.CoordinateTransformation(wgs84, utm)
    kmzs = sorted(f for f in os.listdir(out) if f.endswith(".kmz"))
    if not kmzs:
        fault(f"no .kmz in {out}")
    files = []
    for f in kmzs:
        stem = f[: -len(".kmz")]
        if stem not in sorties:
            fault(f"{f}: no sortie {stem} in plan.json")
            continue
        files.append(check_kmz(os.path.join(out, f), plan, sorties[stem], geoid, transform))
    print(json.dumps({"files": files, "faults": faults}, indent=1))
    sys.exit(1 if faults else 0)


if __name__ == "__main__":
    main()
