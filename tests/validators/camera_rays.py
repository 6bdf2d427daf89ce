"""The rays of a pinhole camera pitched along its track: shared by the
photo checkers (numpy only, so GDAL's Python can import it too)."""
import math

import numpy as np


def rays(cam, pitch, heading):
    """Unit rays (east, north, up) through the corners (near left, near
    right, far right, far left) and the centre of a camera pitched `pitch`
    degrees (-90 nadir) on a track of bearing `heading`."""
    tilt = math.radians(90.0 + pitch)
    hd = math.radians(heading)
    rot_x = np.array([[1, 0, 0],
                      [0, math.cos(tilt), -math.sin(tilt)],
                      [0, math.sin(tilt), math.cos(tilt)]])
    # Track frame (across, along, up) to grid (east, north, up).
    to_grid = np.array([[math.cos(hd), math.sin(hd), 0],
                        [-math.sin(hd), math.cos(hd), 0],
                        [0, 0, 1]])
    w, hh, f = cam["sensor_width_mm"] / 2, cam["sensor_height_mm"] / 2, cam["focal_length_mm"]
    if cam.get("orientation") == "portrait":
        w, hh = hh, w
    out = []
    for sx, sy in [(-w, -hh), (w, -hh), (w, hh), (-w, hh), (0.0, 0.0)]:
        d = to_grid @ (rot_x @ np.array([sx, sy, -f]))
        out.append(d / np.linalg.norm(d))
    return out
