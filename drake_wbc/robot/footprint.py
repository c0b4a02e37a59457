"""The base's footprint at the start of a run: the footprint in the plane
and the height of the base's deck (the robot description's), and
the check that no static obstacle of a scene overlaps the footprint at
the base's initial pose, which a Scenario (drake_wbc.experiments.scenario)
runs."""

import numpy as np

from drake_wbc.robot.description import shipped_robot

FOOTPRINT_HALF_SIZES = tuple(shipped_robot().base.footprint_half_sizes)
"""The shipped base's footprint, half length and half width in m (its
description's: the model's 0.8 x 0.6 m chassis)."""

BASE_HEIGHT = shipped_robot().base.height
"""The height of the shipped base's deck in m (its description's): a box
whose bottom is higher may overhang the base."""


def check_start_is_free(scene, base_pose):
    """Checks that no static obstacle overlaps the base's footprint at
    its initial pose [x, y, yaw]: no cylinder, and no box reaching below
    BASE_HEIGHT (the footprint and each box as rectangles in the plane,
    by separating axes)."""
    x, y, yaw = base_pose
    footprint = _rectangle(x, y, *FOOTPRINT_HALF_SIZES, yaw)
    for i, cylinder in enumerate(scene.cylinders):
        c, s = np.cos(yaw), np.sin(yaw)
        offset = np.asarray(cylinder.position) - [x, y]
        local = np.array([c * offset[0] + s * offset[1],
                          -s * offset[0] + c * offset[1]])
        nearest = np.clip(local, -np.array(FOOTPRINT_HALF_SIZES),
                          FOOTPRINT_HALF_SIZES)
        if np.linalg.norm(local - nearest) < cylinder.radius:
            _overlap(f"scene.cylinders[{i}]", cylinder.name, base_pose)
    for i, box in enumerate(scene.boxes):
        if box.center[2] - box.size[2] / 2 >= BASE_HEIGHT:
            continue
        corners = _rectangle(box.center[0], box.center[1], box.size[0] / 2,
                             box.size[1] / 2, box.yaw)
        if not _separated(footprint, corners):
            _overlap(f"scene.boxes[{i}]", box.name, base_pose)


def _overlap(where, name, base_pose):
    raise ValueError(
        f"{where} ({name!r}) is not allowed with station.initial_base_pose "
        f"= {list(base_pose)}: it overlaps the base's "
        f"{2 * FOOTPRINT_HALF_SIZES[0]} x {2 * FOOTPRINT_HALF_SIZES[1]} m "
        "footprint at the start")


def _rectangle(cx, cy, hx, hy, yaw):
    """The corners (4, 2) of a rectangle of half sizes hx, hy turned by
    `yaw` about its centre (cx, cy)."""
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    return local @ np.array([[c, s], [-s, c]]) + [cx, cy]


def _separated(a, b):
    """True when the convex polygons with corners `a` and `b` do not
    overlap (an edge normal of one separates them)."""
    for corners in (a, b):
        for k in range(len(corners)):
            edge = corners[(k + 1) % len(corners)] - corners[k]
            normal = np.array([-edge[1], edge[0]])
            pa, pb = a @ normal, b @ normal
            if pa.max() <= pb.min() or pb.max() <= pa.min():
                return True
    return False
