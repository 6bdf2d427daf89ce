"""The plan's photo-count rule (planner-core coverage::photo_count), which
every validator counting photos along a lane uses: one photo at a lane's
start, then one every trigger distance, the far one counted when the lane
reaches within 1 cm of it (the files round positions to about a
millimetre)."""
import math

PHOTO_END_TOLERANCE_M = 0.01


def photo_count(length, spacing):
    return math.floor((length + PHOTO_END_TOLERANCE_M) / spacing) + 1
