"""Least-cost routes by scikit-image's MCP_Geometric, to check and time
terraplan's route planner against.

    mcp_route.py random DIR --seed N --count K --size WxH
        writes K random costmap GeoTIFFs (page 1 the Float32 cost with NaN
        nodata, page 2 the Byte class with nodata 0, 2 m cells in
        EPSG:32618: the layout `terraplan costmap` writes, by tifffile) to
        DIR, half of them with obstacles, and DIR/cases.json:
        for each, the file, start and goal cells and their UTM centres, and
        MCP_Geometric's cost between them.
    mcp_route.py cost COSTMAP.tif ROW,COL ROW,COL
        MCP_Geometric's cost between two cells of a costmap GeoTIFF, and
        the seconds it took (JSON on stdout).
    mcp_route.py dijkstra COSTMAP.tif ROW,COL ROW,COL
        the cheapest cost between two cells by a plain Dijkstra with
        terraplan's rules (8-connected, a diagonal step only when both
        cells it passes between are traversable, step length × the mean
        of the two costs), written here independently (JSON).
    mcp_route.py pick COSTMAP.tif
        the traversable cells nearest the top-left and bottom-right corners
        within the largest 8-connected traversable region, a cell of class
        3 (step) and a traversable cell outside that region (JSON).
    mcp_route.py block ROUTE.json OUT.geojson [LENGTH_M [HALF_WIDTH_M]]
        a polygon covering LENGTH_M (default 20) of a `terraplan route`
        route around the middle of its length, HALF_WIDTH_M (default 2)
        either side, as GeoJSON in WGS84 (shapely buffers it in UTM); prints
        the robot's position 20 m before the stretch along the route
        (`robot_utm`), where it would see the block.

MCP_Geometric with fully_connected=True costs a step as its length times
the mean of the two cells' costs: terraplan's `integrated` rule. Obstacles
(NaN costs) are walls (infinite cost). Unlike terraplan, MCP lets a
diagonal step pass between two wall cells, so with obstacles its cost may
be lower, never higher.
"""

import json
import sys
import time

import numpy as np
import tifffile
from scipy import ndimage
from skimage.graph import MCP_Geometric

CELL_M = 2.0
ORIGIN = (472000.0, 4295000.0)  # top-left corner, UTM 18N (EPSG:32618)


def read_bands(path):
    with tifffile.TiffFile(path) as tif:
        page = tif.pages[0]
        data = page.asarray()
        planar = page.planarconfig == 2
        tags = page.tags
        scale = tags["ModelPixelScaleTag"].value
        tie = tags["ModelTiepointTag"].value
    return data, planar, scale, tie


def read_class(path):
    """The class codes: page 2 of a costmap, or band 2 of its first page (as
    terraplan wrote costmaps before the class page) when page 2 is missing
    or only an overview or mask of page 1."""
    with tifffile.TiffFile(path) as tif:
        if len(tif.pages) > 1 and not (tif.pages[1].is_reduced or tif.pages[1].is_mask):
            return tif.pages[1].asarray()
        page = tif.pages[0]
        data = page.asarray()
        return data[1] if page.planarconfig == 2 else data[..., 1]


def read_costmap(path):
    """Band 1 (cost, float64 with inf for NaN), the cell size (x, y) and
    the top-left corner."""
    data, planar, scale, tie = read_bands(path)
    # A 2-band page reads as (2, h, w) when planar, (h, w, 2) when chunky.
    if data.ndim == 3:
        cost = data[0] if planar else data[..., 0]
    else:
        cost = data
    cost = cost.astype(np.float64)
    cost[~np.isfinite(cost)] = np.inf
    origin = (tie[3] - tie[0] * scale[0], tie[4] + tie[1] * scale[1])
    return cost, (scale[0], scale[1]), origin


def mcp_cost(cost, cell, start, goal):
    t = time.perf_counter()
    m = MCP_Geometric(cost, fully_connected=True, sampling=(cell[1], cell[0]))
    cum, _ = m.find_costs([start], [goal])
    return float(cum[goal]), time.perf_counter() - t


def write_costmap(path, cost):
    cls = np.where(np.isfinite(cost), 1, 3).astype(np.uint8)
    geokeys = (1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 32618)
    georef = [
        (33550, "d", 3, (CELL_M, CELL_M, 0.0), True),
        (33922, "d", 6, (0.0, 0.0, 0.0, ORIGIN[0], ORIGIN[1], 0.0), True),
        (34735, "H", len(geokeys), geokeys, True),
    ]
    with tifffile.TiffWriter(path) as tif:
        # GDAL_NODATA counts its terminating NUL.
        for data, nodata in [(cost.astype(np.float32), "nan"), (cls, "0")]:
            tif.write(
                data,
                photometric="minisblack",
                metadata=None,
                extratags=georef + [(42113, "s", len(nodata) + 1, nodata, True)],
            )


def centre_utm(row, col):
    return [ORIGIN[0] + (col + 0.5) * CELL_M, ORIGIN[1] - (row + 0.5) * CELL_M]


def random_cases(out, seed, count, w, h):
    rng = np.random.default_rng(seed)
    cases = []
    for k in range(count):
        # Smooth costs in [1, 20]: blurred noise, like terrain costs.
        noise = ndimage.gaussian_filter(rng.standard_normal((h, w)), 3.0)
        noise = (noise - noise.min()) / (np.ptp(noise) or 1.0)
        cost = 1.0 + 19.0 * noise ** rng.uniform(0.5, 3.0)
        obstacles = k % 2 == 1
        if obstacles:
            walls = ndimage.gaussian_filter(rng.standard_normal((h, w)), 2.0)
            cost[walls > np.quantile(walls, 0.8)] = np.nan
        finite = np.isfinite(cost)
        labels, n = ndimage.label(finite, structure=np.ones((3, 3)))
        biggest = 1 + int(np.argmax(ndimage.sum(finite, labels, range(1, n + 1))))
        rows, cols = np.nonzero(labels == biggest)
        i, j = rng.choice(len(rows), 2, replace=False)
        start, goal = (int(rows[i]), int(cols[i])), (int(rows[j]), int(cols[j]))
        path = f"{out}/random{k}.tif"
        write_costmap(path, cost)
        mcp = cost.astype(np.float64)
        mcp[~np.isfinite(mcp)] = np.inf
        value, _ = mcp_cost(mcp, (CELL_M, CELL_M), start, goal)
        cases.append(
            {
                "file": path,
                "obstacles": obstacles,
                "start": list(start),
                "goal": list(goal),
                "start_utm": centre_utm(*start),
                "goal_utm": centre_utm(*goal),
                "mcp_cost": value,
            }
        )
    with open(f"{out}/cases.json", "w") as f:
        json.dump(cases, f, indent=1)


def pick(path):
    cost, _, _ = read_costmap(path)
    finite = np.isfinite(cost)
    labels, n = ndimage.label(finite, structure=np.ones((3, 3)))
    if n == 0:
        raise SystemExit("no traversable cell")
    biggest = 1 + int(np.argmax(ndimage.sum(finite, labels, range(1, n + 1))))
    rows, cols = np.nonzero(labels == biggest)
    h, w = cost.shape
    a = int(np.argmin(rows.astype(np.int64) ** 2 + cols.astype(np.int64) ** 2))
    b = int(np.argmin((h - 1 - rows.astype(np.int64)) ** 2 + (w - 1 - cols.astype(np.int64)) ** 2))
    cls = read_class(path)
    step = np.argwhere(cls == 3)
    island = np.argwhere(finite & (labels != biggest))
    first = lambda cells: [int(v) for v in cells[0]] if len(cells) else None
    return {
        "start": [int(rows[a]), int(cols[a])],
        "goal": [int(rows[b]), int(cols[b])],
        "step": first(step),
        "island": first(island),
    }


def block(route_path, out_path, length=20.0, half_width=2.0):
    from pyproj import Transformer
    import shapely
    from shapely.geometry import LineString, mapping
    from shapely.ops import substring

    with open(route_path) as f:
        route = json.load(f)
    line = LineString([(w["easting"], w["northing"]) for w in route["waypoints"]])
    mid = line.length / 2.0
    stretch = substring(line, max(0.0, mid - length / 2.0), min(line.length, mid + length / 2.0))
    area = stretch.buffer(half_width, cap_style="flat")
    to_wgs84 = Transformer.from_crs(route["utm_epsg"], 4326, always_xy=True)
    area = shapely.transform(area, lambda xy: np.column_stack(to_wgs84.transform(xy[:, 0], xy[:, 1])))
    with open(out_path, "w") as f:
        json.dump(mapping(area), f)
    robot = line.interpolate(max(0.0, mid - length / 2.0 - 20.0))
    return {
        "stretch_m": stretch.length,
        "area_m2": stretch.buffer(half_width, cap_style="flat").area,
        "robot_utm": [robot.x, robot.y],
    }


def dijkstra(path, start, goal):
    import heapq

    cost, (sx, sy), _ = read_costmap(path)
    h, w = cost.shape
    ok = np.isfinite(cost)
    dist = np.full((h, w), np.inf)
    dist[start] = 0.0
    heap = [(0.0, start)]
    diag = (sx * sx + sy * sy) ** 0.5
    while heap:
        d, (r, c) = heapq.heappop(heap)
        if (r, c) == goal:
            return d
        if d > dist[r, c]:
            continue
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dr == 0 and dc == 0:
                    continue
                nr, nc = r + dr, c + dc
                if not (0 <= nr < h and 0 <= nc < w) or not ok[nr, nc]:
                    continue
                if dr != 0 and dc != 0 and not (ok[r, nc] and ok[nr, c]):
                    continue
                step = diag if dr and dc else (sx if dc else sy)
                nd = d + step * (cost[r, c] + cost[nr, nc]) / 2.0
                if nd < dist[nr, nc]:
                    dist[nr, nc] = nd
                    heapq.heappush(heap, (nd, (nr, nc)))
    return float("inf")


def cell(text):
    r, c = text.split(",")
    return int(r), int(c)


def main(argv):
    if argv[1] == "random":
        args = dict(zip(argv[3::2], argv[4::2]))
        w, h = (int(v) for v in args.get("--size", "120x90").split("x"))
        random_cases(argv[2], int(args.get("--seed", "1")), int(args.get("--count", "10")), w, h)
    elif argv[1] == "cost":
        cost, size, _ = read_costmap(argv[2])
        value, seconds = mcp_cost(cost, size, cell(argv[3]), cell(argv[4]))
        print(json.dumps({"cost": value, "seconds": seconds, "cells": int(cost.size)}))
    elif argv[1] == "dijkstra":
        print(json.dumps({"cost": dijkstra(argv[2], cell(argv[3]), cell(argv[4]))}))
    elif argv[1] == "block":
        extra = [float(v) for v in argv[4:6]]
        print(json.dumps(block(argv[2], argv[3], *extra)))
    elif argv[1] == "pick":
        print(json.dumps(pick(argv[2])))
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main(sys.argv)
