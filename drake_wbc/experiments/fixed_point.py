"""Experiment 2 of the paper (Sec. V, "Robust Whole-body Control", Fig.
"wbc_avoid"): the end effector holds still while a person approaches the
base, with the null-space gain k_n and the compensation switch s_c changed
on the way (diagrams/fixed_point.yaml).

An approach is a stretch of time in which a person is within d_th of the
base's footprint (the repulsive field's reach, after eq. (cdmp-base));
stretches less than `APPROACH_GAP` apart count as one. Everything is
measured from ground truth, except the integrated deviation
x_dist, y_dist = int delta_V_ee dt of eq. (deviation), which is the
controller's own estimate (the paper's Fig. "wbc_avoid" plots it).

Metrics of `compute_metrics` (a run's keys are prefixed with
"<run>." when the scenario has several runs; NaN where a stretch of time
has no samples, "nan" in summary.json):

- approaches: how many approaches there were.
- approach_<k>_start_s, approach_<k>_end_s: when approach k began and
  ended (k = 1, 2, ...).
- approach_<k>_compensation_switch: s_c when approach k began.
- approach_<k>_min_person_distance_m: the person's closest approach to the
  footprint during approach k.
- approach_<k>_max_ee_deviation_close_m: the end effector's largest
  distance from its starting position while the person was close.
- approach_<k>_max_ee_deviation_after_m: the same from the person's
  leaving to the next approach (or the end of the run).
- approach_<k>_min_capability: the lowest C_m during approach k.
- max_ee_deviation_m, final_ee_deviation_m: over the run, and at its end.
- max_base_displacement_m: the base's largest distance (x-y) from its
  starting position.
- min_person_distance_m: the closest approach of any person to the
  footprint.
- min_capability_compensation_on, min_capability_compensation_off: the
  lowest C_m while s_c = 1, and while s_c = 0.
- capability_band_lower, capability_band_upper: C_m^l, C_m^u of eq.
  (transition).
- max_integrated_deviation_m: the largest norm of (x_dist, y_dist).
"""

import math

import numpy as np

from drake_wbc.experiments.common import (
    integrated_deviation,
    metrics_of_each_run,
    new_figure,
    person_distances,
    save_figure,
    schedule_values,
)
from drake_wbc.experiments.scenario import controller_for

APPROACH_GAP = 0.5
"""Approaches less than this many seconds apart are merged (s)."""


def approach_intervals(time, distance, threshold, gap=APPROACH_GAP):
    """The stretches where `distance` < `threshold`, as (start, end) index
    pairs (end exclusive); stretches less than `gap` s apart are merged."""
    close = np.asarray(distance) < threshold
    edges = np.diff(np.concatenate([[0], close.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    intervals = []
    for start, end in zip(starts, ends, strict=True):
        if intervals and time[start] - time[intervals[-1][1] - 1] < gap:
            intervals[-1] = (intervals[-1][0], end)
        else:
            intervals.append((start, end))
    return intervals


def compensation_switch(scenario, log):
    """s_c (N,) over the run."""
    return schedule_values(
        scenario.task.compensation_switch, log.time,
        scenario.controller.compensator.compensation_switch)[:, 0]


def null_space_gain(scenario, log):
    """k_n (N,) over the run."""
    return schedule_values(
        scenario.task.null_space_gain, log.time,
        scenario.controller.distributor.null_space_gain)[:, 0]


def _max(values):
    return float(np.max(values)) if len(values) else math.nan


def _min(values):
    return float(np.min(values)) if len(values) else math.nan


def run_metrics(scenario, log):
    """The metrics of one run (see the module's docstring)."""
    ee = log["truth.end_effector_pose"][:, :3]
    ee_offset = np.linalg.norm(ee - ee[0], axis=1)
    base = log["truth.base_pose"][:, :2]
    capability = log["capability"][:, 0]
    s_c = compensation_switch(scenario, log)
    distance = person_distances(scenario, log)
    d_th = scenario.controller.base_cdmp.repulsion.d_th
    intervals = approach_intervals(log.time, distance, d_th)
    band = controller_for(scenario).capability_band
    dist = integrated_deviation(log)
    metrics = {"approaches": len(intervals)}
    for k, (start, end) in enumerate(intervals, start=1):
        after_end = (intervals[k][0] if k < len(intervals)
                     else len(log.time))
        key = f"approach_{k}_"
        metrics.update({
            key + "start_s": float(log.time[start]),
            key + "end_s": float(log.time[end - 1]),
            key + "compensation_switch": float(s_c[start]),
            key + "min_person_distance_m": _min(distance[start:end]),
            key + "max_ee_deviation_close_m": _max(ee_offset[start:end]),
            key + "max_ee_deviation_after_m": _max(ee_offset[end:after_end]),
            key + "min_capability": _min(capability[start:end]),
        })
    metrics.update({
        "max_ee_deviation_m": float(np.max(ee_offset)),
        "final_ee_deviation_m": float(ee_offset[-1]),
        "max_base_displacement_m": float(np.max(np.linalg.norm(
            base - base[0], axis=1))),
        "min_person_distance_m": float(np.min(distance)),
        "min_capability_compensation_on": _min(capability[s_c > 0.5]),
        "min_capability_compensation_off": _min(capability[s_c <= 0.5]),
        "capability_band_lower": float(band.lower),
        "capability_band_upper": float(band.upper),
        "max_integrated_deviation_m": float(np.max(np.linalg.norm(
            dist[:, :2], axis=1))),
    })
    return metrics


def compute_metrics(scenario, logs):
    """The metrics of every run (see the module's docstring)."""
    return metrics_of_each_run(scenario, logs, run_metrics)


def draw_figures(scenario, logs, folder):
    """One figure per run mirroring the paper's Fig. "wbc_avoid",
    `wbc_avoid_<run>.png`: base and end-effector velocities, x_dist and
    y_dist, C_m with its band, k_n and s_c, and the person's distance.
    Approaches are shaded."""
    import matplotlib.pyplot as plt

    paths = []
    band = controller_for(scenario).capability_band
    d_th = scenario.controller.base_cdmp.repulsion.d_th
    for name, log in logs.items():
        t = log.time
        distance = person_distances(scenario, log)
        fig, axes = new_figure(5, title=f"{scenario.description} ({name})",
                               width=9.0)
        command = log["base.velocity_command"]
        axes[0].plot(t, command[:, 0], label="$V^{ref}_{b,x}$")
        axes[0].plot(t, command[:, 1], label="$V^{ref}_{b,y}$")
        loop = log["truth.base_loop_velocity"]
        axes[0].plot(t, loop[:, 0], "--", lw=0.8, label="base $v_x$ (true)")
        axes[0].plot(t, loop[:, 1], "--", lw=0.8, label="base $v_y$ (true)")
        axes[0].set_ylabel("base (m/s)")
        ee_velocity = log["truth.end_effector_velocity"]
        axes[1].plot(t, ee_velocity[:, 0], label="$v_x$")
        axes[1].plot(t, ee_velocity[:, 1], label="$v_y$")
        axes[1].plot(t, ee_velocity[:, 2], lw=0.8, label="$v_z$")
        axes[1].set_ylabel("end effector\n(m/s, true)")
        dist = integrated_deviation(log)
        ee = log["truth.end_effector_pose"][:, :3]
        axes[2].plot(t, dist[:, 0], label="$x_{dist}$")
        axes[2].plot(t, dist[:, 1], label="$y_{dist}$")
        axes[2].plot(t, ee[:, 0] - ee[0, 0], ":", label="$x_{ee}$ (true)")
        axes[2].plot(t, ee[:, 1] - ee[0, 1], ":", label="$y_{ee}$ (true)")
        axes[2].set_ylabel("deviation (m)")
        axes[3].axhspan(band.lower, band.upper, color="tab:red", alpha=0.15,
                        label="band")
        axes[3].plot(t, log["capability"][:, 0], color="k", label="$C_m$")
        axes[3].set_ylabel("$C_m$")
        switches = axes[3].twinx()
        switches.plot(t, null_space_gain(scenario, log), color="tab:green",
                      label="$k_n$")
        switches.plot(t, 0.1 * compensation_switch(scenario, log),
                      color="tab:purple", ls="--", label="$0.1\\,s_c$")
        switches.set_ylim(-0.01, 0.12)
        switches.set_ylabel("$k_n$, $0.1\\,s_c$")
        switches.legend(loc="lower right", fontsize=7)
        axes[4].plot(t, np.minimum(distance, 2.0), label="person")
        axes[4].axhline(d_th, color="tab:red", ls="--", lw=0.8,
                        label="$d_{th}$")
        axes[4].set_ylabel("distance (m)")
        for start, end in approach_intervals(t, distance, d_th):
            for axis in axes:
                axis.axvspan(t[start], t[end - 1], color="0.85", alpha=0.5)
        for axis in axes:
            axis.legend(loc="upper left", fontsize=7, ncol=4)
        paths.append(save_figure(fig, folder, f"wbc_avoid_{name}"))
        plt.close(fig)
    return paths
