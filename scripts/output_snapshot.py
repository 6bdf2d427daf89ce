"""Plans a fixed set of real inputs with one `terraplan` binary and writes
every output file under OUTDIR, so that two builds can be compared byte for
byte (see compare-outputs.sh). Usage: output_snapshot.py BINARY OUTDIR"""

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT.parent / "shared" / "data"
EXAMPLES = ROOT / "examples"

# Files whose content holds wall-clock timings (the D* Lite replan writes
# its time next to a search from scratch): compared by name only. Route
# files also carry their search time in `*_ms` members, masked.
TIMED = {"replanned/timing.json"}
MILLISECONDS = re.compile(r'("[a-z_]+_ms"): [0-9.eE+-]+')


def run(binary, args, out):
    out.mkdir(parents=True, exist_ok=True)
    done = subprocess.run([str(binary), *args], capture_output=True, text=True)
    (out / "exit-status.txt").write_text(f"{done.returncode}\n{done.stderr}")


def params(out, **fields):
    base = json.loads((EXAMPLES / "params.json").read_text())
    base.update(fields)
    path = out.parent / f"{out.name}.params.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(base))
    return str(path)


def polygon_file(out, name, lon0, lat0, lon1, lat1):
    ring = [[lon0, lat0], [lon1, lat0], [lon1, lat1], [lon0, lat1], [lon0, lat0]]
    path = out / f"{name}.geojson"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    return str(path)


def main():
    binary, outdir = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
    inputs = outdir / "_inputs"
    field, nfz = str(EXAMPLES / "field.geojson"), str(EXAMPLES / "field-nfz.geojson")

    # Surveys: the example field with its NFZs, one UAV and a flock with
    # batteries (sorties); Fields2Cover's two-cell field at a fixed angle.
    s = outdir / "survey-example"
    run(binary, ["survey", "--roi", field, "--no-fly", nfz, "--params", params(s), "--out", str(s)], s)
    s = outdir / "survey-flock"
    uavs = [{"id": f"u{i}", "start": [6.0620 + 0.001 * i, 51.5110], "max_flight_time_s": 600}
            for i in range(3)]
    run(binary, ["survey", "--roi", field, "--no-fly", nfz, "--params",
                 params(s, uavs=uavs, altitude_m=40), "--out", str(s)], s)
    s = outdir / "survey-f2c-two-cells"
    run(binary, ["survey", "--roi", str(DATA / "polygons" / "fields2cover__test_2_cell.json"),
                 "--params", params(s, slice_angle_deg=30, uavs=[]), "--out", str(s)], s)

    # Terrain following over a real DSM with the buildings as NFZs.
    s = outdir / "survey-terrain-buildings"
    roi = polygon_file(inputs, "opengeos-roi", -77.0550, 38.8090, -77.0502, 38.8122)
    run(binary, ["survey", "--roi", roi, "--no-fly",
                 str(DATA / "polygons" / "opengeos__elevation_buildings.geojson"),
                 "--dem", str(DATA / "dems" / "opengeos_data__elevation_dtm.tif"),
                 "--params", params(s, altitude_m=50, altitude_frame="amsl", nfz_clearance_m=2, allow_partial_dem=True,
                                    uavs=[{"id": "u", "start": [-77.0548, 38.8092]}]),
                 "--out", str(s)], s)

    # Costmaps with every layer, and a route with a blocked area.
    dem = str(DATA / "dems" / "opengeos_data__elevation_dtm.tif")
    c = outdir / "costmap-opengeos"
    run(binary, ["costmap", dem, "--layers",
                 "slope,zcomp,step,inflation", "--out", str(c)], c)
    c2 = outdir / "costmap-codem"
    run(binary, ["costmap", str(DATA / "dems" / "codem__AOI-DigitalSurfaceModel.tif"),
                 "--vehicle", "small-wheeled", "--out", str(c2)], c2)
    r = outdir / "route-opengeos"
    block = polygon_file(inputs, "block", -77.0530, 38.8095, -77.0520, 38.8120)
    run(binary, ["route", str(c / "costmap.tif"), "--from", "utm:321573,4297587",
                 "--to", "utm:321971,4297987", "--dem", dem, "--speed", "2", "--block", block,
                 "--out", str(r)], r)

    for path in outdir.rglob("*"):
        rel = path.relative_to(outdir).as_posix()
        if path.is_file() and any(rel.endswith(t) for t in TIMED):
            path.write_text("(timings: not compared)\n")
        elif path.is_file() and path.name == "route.json":
            path.write_text(MILLISECONDS.sub(r'\1: "(timing)"', path.read_text()))


if __name__ == "__main__":
    main()
