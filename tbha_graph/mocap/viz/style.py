"""Colours shared by the viz nodes, so the overlay video, the error plot and the skeleton sheet agree.

Colours are BGR ``uint8`` triples (OpenCV's order); :func:`rgb` converts one for matplotlib.
"""
from __future__ import annotations

from ..skeleton import JOINT_NAMES

#: 2D tracks (the tracker's output): yellow
TRACKS_BGR = (0, 215, 255)
#: the 3D motion reprojected with the camera: magenta
REPROJECTED_BGR = (255, 0, 255)
#: ground truth: green
TRUTH_BGR = (60, 200, 0)
#: the actor's left side (+x in the rest pose): blue; right side: red; spine and head: dark grey
LEFT_BGR = (200, 90, 30)
RIGHT_BGR = (40, 40, 220)
CENTRE_BGR = (40, 40, 40)
#: curves in plots (on white): 3D error dark blue; the tracks' colour darkened to gold for contrast
ERROR3D_BGR = (160, 80, 0)
TRACKS_PLOT_BGR = (0, 160, 210)
#: frames whose labelling is doubtful (issue 13): orange
DOUBTFUL_BGR = (0, 120, 255)


def rgb(bgr: tuple[int, int, int]) -> tuple[float, float, float]:
    """A BGR ``uint8`` colour as a matplotlib RGB triple in 0..1."""
    b, g, r = bgr
    return (r / 255.0, g / 255.0, b / 255.0)


def side_color(joint: int) -> tuple[int, int, int]:
    """BGR colour of the bone ending at ``joint`` by body side (left blue, right red, centre grey)."""
    name = JOINT_NAMES[joint]
    if name.startswith("left_"):
        return LEFT_BGR
    if name.startswith("right_"):
        return RIGHT_BGR
    return CENTRE_BGR
