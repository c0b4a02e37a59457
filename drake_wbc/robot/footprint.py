"""The base's footprint at the start of a run: the check that no static
obstacle of a scene overlaps the footprint of a robot's base (its
description's footprint in the plane and the height of its deck) at the
base's initial pose, which a Scenario (drake_wbc.experiments.scenario)
runs."""

import numpy as np


def check_start_is_free(scene, base_pose, base):
    """Checks that no static obstacle overlaps the base's footprint at
    its initial pose [x, y, yaw]: no cylinder, and no box reaching below
    the base's deck (the footprint and each box as rectangles in the
    plane, by separating axes).

    Args:
        scene: the Scene (drake_wbc.station.scene).
        base_pose: [x, y, yaw] of T_b in the world.
        base: the robot's BaseDescription (its footprint_half_sizes and
            height).

    Raises:
        ValueError: naming the obstacle and the pose.
    """
    x, y, yaw = base_pose
    half_sizes = tuple(base.footprint_half_sizes)
    footprint = _rectangle(x, y, *half_sizes, yaw)
    for i, cylinder in enumerate(scene.cylinders):
        c, s = np.cos(yaw), np.sin(yaw)
        offset = np.asarray(cylinder.position) - [x, y]
        local = np.array([c * offset[0] + s * offset[1],
                          -s * offset[0] + c * offset[1]])
        nearest = np.clip(local, -np.array(half_sizes), half_sizes)
        if np.linalg.norm(local - nearest) < cylinder.radius:
            _overlap(f"scene.cylinders[{i}]", cylinder.name, base_pose,
                     half_sizes)
    for i, box in enumerate(scene.boxes):
        if box.center[2] - box.size[2] / 2 >= base.height:
            continue
        corners = _rectangle(box.center[0], box.center[1], box.size[0] / 2,
                             box.size[1] / 2, box.yaw)
        if not _separated(footprint, corners):
            _overlap(f"scene.boxes[{i}]", box.name, base_pose, half_sizes)


def _overlap(where, name, base_pose, half_sizes):
    raise ValueError(
        f"{where} ({name!r}) is not allowed with station.initial_base_pose "
        f"= {list(base_pose)}: it overlaps the base's "
        f"{2 * half_sizes[0]} x {2 * half_sizes[1]} m footprint at the "
        "start")


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
