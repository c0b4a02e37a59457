"""Experiment 3 of the paper (Sec. V, Fig. "obst_avoid"): the end effector
tracks a straight line at 0.3 m/s while the base, which carries the
motion, swerves around static obstacles and a person; the arm compensates
the swerves, so the end effector stays on its line (diagrams/
line_tracking.yaml).

The line is the end effector's starting position and the direction of the
first non-zero reference velocity (x-y); the base's line is its own
starting position and the same direction. Lateral deviations are the
signed distances from these lines, from ground truth, over the samples
from the start of the motion (the first non-zero reference velocity) to
the end of the run.

Metrics of `compute_metrics` (a run's keys are prefixed with "<run>." when
the scenario has several runs; None where undefined):

- ee_lateral_rms_m, ee_lateral_peak_m: RMS and largest absolute lateral
  deviation of the end effector.
- base_lateral_rms_m, base_lateral_peak_m: the same for the base (T_b's
  origin, the footprint's centre).
- lateral_rms_ratio, lateral_peak_ratio: end effector over base.
- ee_height_peak_deviation_m: the end effector's largest change of height.
- ee_travel_m, base_travel_m: distance covered along the line.
- min_static_obstacle_distance_m, min_person_distance_m: the closest
  approach of the footprint to any static obstacle, and to any person.
- closest_approach_<name>_m: the same for each obstacle and person of the
  scene, by name.
"""

from dataclasses import replace

import numpy as np

from drake_wbc.experiments.common import (
    metrics_of_each_run,
    obstacle_distances,
    person_distances,
    save_figure,
    static_distances,
)
from drake_wbc.experiments.scenario import footprint_of

ARROW_PERIOD = 1.0
"""Seconds between the position-velocity arrows of the x-y plot."""

FOOTPRINT_PERIOD = 2.0
"""Seconds between the footprints drawn in the x-y plot."""


def line_direction(log):
    """The unit x-y direction (2,) of the first non-zero reference velocity
    (world x if there is none) and the index where the motion starts."""
    speed = np.linalg.norm(log["reference_velocity"][:, :2], axis=1)
    moving = np.flatnonzero(speed > 1e-9)
    if not len(moving):
        return np.array([1.0, 0.0]), 0
    v = log["reference_velocity"][moving[0], :2]
    return v / np.linalg.norm(v), int(moving[0])


def lateral_deviations(log):
    """Signed lateral deviations (N,) of the end effector and of the base
    from their lines (left of the direction of travel positive), their
    progress along the lines (N,) each, and the motion's first index."""
    direction, start = line_direction(log)
    normal = np.array([-direction[1], direction[0]])
    ee = log["truth.end_effector_pose"][:, :2]
    base = log["truth.base_pose"][:, :2]
    ee_rel, base_rel = ee - ee[0], base - base[0]
    return (ee_rel @ normal, base_rel @ normal, ee_rel @ direction,
            base_rel @ direction, start)


def _ratio(numerator, denominator):
    return float(numerator / denominator) if denominator > 0.0 else None


def _scene_objects(scene):
    """(name, scene holding that object alone, the person's index in the
    scene's people or None) per object."""
    empty = replace(scene, cylinders=[], boxes=[], people=[])
    objects = [(c.name, replace(empty, cylinders=[c]), None)
               for c in scene.cylinders]
    objects += [(b.name, replace(empty, boxes=[b]), None)
                for b in scene.boxes]
    objects += [(p.name, replace(empty, people=[p]), k)
                for k, p in enumerate(scene.people)]
    return objects


def _least(distance):
    """The least of `distance` (N,), None where it is inf (nothing to
    measure to)."""
    value = float(np.min(distance))
    return value if np.isfinite(value) else None


def _closest(scene, log, person, footprint):
    """The closest approach of the footprint to the one object of
    `scene`; for the scene's person of index `person`, from its own
    columns of truth.people_positions (all of them measured every
    person's centre with this one's radius)."""
    people = None if person is None else log[
        "truth.people_positions"][:, 2 * person:2 * person + 2]
    return _least(obstacle_distances(scene, log["truth.base_pose"],
                                     footprint, people))


def run_metrics(scenario, log):
    """The metrics of one run (see the module's docstring)."""
    ee_lat, base_lat, ee_along, base_along, start = lateral_deviations(log)
    ee_lat, base_lat = ee_lat[start:], base_lat[start:]
    ee_rms = float(np.sqrt(np.mean(ee_lat**2)))
    base_rms = float(np.sqrt(np.mean(base_lat**2)))
    ee_peak = float(np.max(np.abs(ee_lat)))
    base_peak = float(np.max(np.abs(base_lat)))
    height = log["truth.end_effector_pose"][:, 2]
    scene, footprint = scenario.scene, footprint_of(scenario)
    metrics = {
        "ee_lateral_rms_m": ee_rms,
        "ee_lateral_peak_m": ee_peak,
        "base_lateral_rms_m": base_rms,
        "base_lateral_peak_m": base_peak,
        "lateral_rms_ratio": _ratio(ee_rms, base_rms),
        "lateral_peak_ratio": _ratio(ee_peak, base_peak),
        "ee_height_peak_deviation_m": float(np.max(np.abs(
            height - height[0]))),
        "ee_travel_m": float(ee_along[-1]),
        "base_travel_m": float(base_along[-1]),
        "min_static_obstacle_distance_m": _least(static_distances(
            scenario, log)),
        "min_person_distance_m": _least(person_distances(scenario, log)),
    }
    for name, alone, person in _scene_objects(scene):
        metrics[f"closest_approach_{name}_m"] = _closest(
            alone, log, person, footprint)
    return metrics


def compute_metrics(scenario, logs):
    """The metrics of every run (see the module's docstring)."""
    return metrics_of_each_run(scenario, logs, run_metrics)


def _draw_scene(axis, scenario, log):
    """The static obstacles, and each person's path with the person drawn
    where they came closest to the base."""
    from matplotlib.patches import Circle, Polygon

    for c in scenario.scene.cylinders:
        axis.add_patch(Circle(c.position, c.radius, color="0.45"))
        axis.annotate(c.name, c.position, ha="center", va="center",
                      fontsize=7, color="w")
    for b in scenario.scene.boxes:
        hx, hy = b.size[0] / 2, b.size[1] / 2
        rot = np.array([[np.cos(b.yaw), -np.sin(b.yaw)],
                        [np.sin(b.yaw), np.cos(b.yaw)]])
        corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
        axis.add_patch(Polygon(corners @ rot.T + b.center[:2],
                               color="tan"))
        axis.annotate(b.name, b.center[:2], ha="center", va="center",
                      fontsize=7)
    people = log.signals.get("truth.people_positions")
    for i, person in enumerate(scenario.scene.people):
        path = people[:, 2 * i:2 * i + 2]
        alone = replace(scenario.scene, cylinders=[], boxes=[],
                        people=[person])
        k = int(np.argmin(obstacle_distances(
            alone, log["truth.base_pose"], footprint_of(scenario), path)))
        axis.plot(path[:, 0], path[:, 1], ":", color="tab:blue", lw=1)
        axis.add_patch(Circle(path[k], person.radius, color="tab:blue",
                              alpha=0.35))
        axis.annotate(f"{person.name} ({log.time[k]:.1f} s)", path[k],
                      ha="center", va="center", fontsize=7)


def _draw_footprints(axis, log, footprint):
    from matplotlib.patches import Polygon

    a, b = footprint
    corners = np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
    step = max(1, int(round(FOOTPRINT_PERIOD / np.median(np.diff(
        log.time)))))
    for x, y, yaw in log["truth.base_pose"][::step]:
        rot = np.array([[np.cos(yaw), -np.sin(yaw)],
                        [np.sin(yaw), np.cos(yaw)]])
        axis.add_patch(Polygon(corners @ rot.T + [x, y], fill=False,
                               ec="tab:orange", lw=0.6, alpha=0.5))


def _half_width(scenario, ee, base):
    """Half the height of the x-y plot: the paths and the static
    obstacles with a margin (people walking far away are cut off)."""
    extent = [np.max(np.abs(ee[:, 1])), np.max(np.abs(base[:, 1])) + 0.4]
    extent += [abs(c.position[1]) + c.radius for c in scenario.scene.cylinders]
    extent += [abs(b.center[1]) + 0.5 * max(b.size[:2])
               for b in scenario.scene.boxes]
    return max(extent) + 0.4


def draw_figures(scenario, logs, folder):
    """One figure per run mirroring the paper's Fig. "obst_avoid",
    `obst_avoid_<run>.png`: the x-y paths of the base and the end effector
    with position-velocity arrows, the footprint every FOOTPRINT_PERIOD s
    and the obstacles; below, the lateral deviations over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for name, log in logs.items():
        fig, (top, bottom) = plt.subplots(
            2, 1, figsize=(10.0, 8.0), height_ratios=[1.4, 1.0])
        fig.suptitle(f"{scenario.description} ({name})", fontsize=10)
        ee = log["truth.end_effector_pose"][:, :2]
        base = log["truth.base_pose"][:, :2]
        _draw_footprints(top, log, footprint_of(scenario))
        _draw_scene(top, scenario, log)
        top.plot(base[:, 0], base[:, 1], color="tab:orange", label="base")
        top.plot(ee[:, 0], ee[:, 1], color="tab:green", label="end effector")
        step = max(1, int(round(ARROW_PERIOD / np.median(np.diff(
            log.time)))))
        v_ee = log["truth.end_effector_velocity"][::step, :2]
        yaw = log["truth.base_pose"][::step, 2]
        v_b = log["truth.base_loop_velocity"][::step, :2]
        v_base = np.column_stack([
            np.cos(yaw) * v_b[:, 0] - np.sin(yaw) * v_b[:, 1],
            np.sin(yaw) * v_b[:, 0] + np.cos(yaw) * v_b[:, 1]])
        for points, velocity, color in ((base[::step], v_base, "tab:orange"),
                                        (ee[::step], v_ee, "tab:green")):
            top.quiver(points[:, 0], points[:, 1], velocity[:, 0],
                       velocity[:, 1], color=color, angles="xy",
                       scale_units="xy", scale=1.0, width=0.003)
        top.set_aspect("equal")
        top.set_ylim(-_half_width(scenario, ee, base),
                     _half_width(scenario, ee, base))
        top.set_xlabel("x (m)")
        top.set_ylabel("y (m)")
        top.grid(True, alpha=0.3)
        top.legend(loc="upper left", fontsize=8)
        top.autoscale_view()
        ee_lat, base_lat, _, _, start = lateral_deviations(log)
        bottom.plot(log.time, base_lat, color="tab:orange", label="base")
        bottom.plot(log.time, ee_lat, color="tab:green", label="end effector")
        bottom.axvline(log.time[start], color="0.5", ls="--", lw=0.8)
        bottom.set_xlabel("time (s)")
        bottom.set_ylabel("lateral deviation (m)")
        bottom.grid(True, alpha=0.3)
        bottom.legend(loc="upper left", fontsize=8)
        paths.append(save_figure(fig, folder, f"obst_avoid_{name}"))
        plt.close(fig)
    return paths
