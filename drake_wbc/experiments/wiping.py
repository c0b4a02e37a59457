"""Experiment 4, force control for a wiping task (paper Sec. V, "Force
Control for Wiping Task", Fig. "wipe").

The tool presses on a wall under the hybrid stiffness/force CDMP of the
arm, eq. (cdmp-arm): force control along x of T_a (S_m = diag(0, 1, 1, 1,
1, 1)) drives F_ext,x to F_d,x while the end effector wipes along the wall
under stiffness control, and a person approaches the base.

The force is the one the controller regulates: F_ext, the wrench the
environment exerts on the tool at the tool centre point in T_a, computed
from the logged FT-300 reading `wrist.wrench_measured` and the measured
arm configuration by the controller's own ExternalWrenchEstimator
(drake_wbc.stages.wrench; the tool's weight removed). The same estimate
of the noise-free weld wrench `truth.wrist_wrench` is reported alongside.
With the README's convention, F_ext,x = F_d,x = -10 N means the wall
pushes the tool back with 10 N: the tool presses 10 N along +x.

Metrics, each prefixed by the run's name and a dot:

- first_contact_s: when |F_ext,x| first exceeds CONTACT_FORCE.
- settle_time_s: the first time after contact from which the force error
  F_ext,x - F_d,x stays within SETTLE_BAND for SETTLE_HOLD.
- force_error_mean_N, force_error_rms_N, force_error_peak_N: the error
  from settle_time_s to the end; force_error_rms_truth_N the RMS of the
  noise-free estimate.
- path_deviation_rms_y_m, path_deviation_rms_z_m,
  path_deviation_rms_angle_rad: the tool's RMS deviation from its
  commanded path (start pose plus the integrated reference twist, in the
  world) in the stiffness directions, after settling.
- wipe_stroke_m, commanded_stroke_m: the peak-to-peak of the tool's and
  the commanded path's y after settling.
- deviation_integral_peak_m: the largest |x_dist|, |y_dist|, the
  integrated end_effector_deviation of eq. (cdmp-wb-error).
- person_min_distance_m: the least distance from the footprint to a
  person; person_close_start_s, person_close_s: when and how long a
  person is within d_th; force_error_rms_before_person_N (settling to
  that start), force_error_rms_person_close_N and
  force_error_peak_person_close_N (while close; NaN without people);
  base_shift_person_close_m: the base's largest displacement while the
  person is close, from where it was when they came close.
- wall_min_distance_m: the least distance from the footprint to a static
  obstacle (the wall), against d_th.
"""

import numpy as np
from pydrake.math import RollPitchYaw
from scipy.spatial.transform import Rotation

from drake_wbc.experiments.common import (
    held_integral,
    integrated_deviation,
    new_figure,
    person_distances,
    sample_period,
    save_figure,
    schedule_values,
    static_distances,
)
from drake_wbc.experiments.scenario import controller_arm
from drake_wbc.stages.wrench import ExternalWrenchEstimator

CONTACT_FORCE = 1.0
"""N: |F_ext,x| above this counts as contact (ten times the FT-300's
noise)."""

SETTLE_BAND = 1.0
"""N: the force has settled once |F_ext,x - F_d,x| stays within this,
10% of the paper's |F_d|."""

SETTLE_HOLD = 0.5
"""s: how long the error must stay in SETTLE_BAND to count as settled."""

METRICS = (
    "first_contact_s", "settle_time_s", "force_error_mean_N",
    "force_error_rms_N", "force_error_peak_N", "force_error_rms_truth_N",
    "path_deviation_rms_y_m", "path_deviation_rms_z_m",
    "path_deviation_rms_angle_rad", "wipe_stroke_m", "commanded_stroke_m",
    "deviation_integral_peak_m", "person_min_distance_m",
    "person_close_start_s", "person_close_s",
    "force_error_rms_before_person_N", "force_error_rms_person_close_N",
    "force_error_peak_person_close_N", "base_shift_person_close_m",
    "wall_min_distance_m",
)
"""The metrics of each run (module docstring), as `<run>.<metric>`."""


def external_wrench(scenario, log, signal="wrist.wrench_measured"):
    """F_ext (N, 6) in T_a at the tool centre point, from the log's sensor
    wrench `signal` (`wrist.wrench_measured` or `truth.wrist_wrench`) and
    `arm.position_measured`, by an ExternalWrenchEstimator on the run's
    robot (`scenario`'s): the reading less the tool's weight, the paper's
    estimate."""
    estimator = ExternalWrenchEstimator(controller_arm(scenario))
    context = estimator.CreateDefaultContext()
    reading = estimator.GetInputPort("wrist_wrench")
    position = estimator.GetInputPort("arm_position")
    output = estimator.GetOutputPort("external_wrench")
    result = np.empty((len(log.time), 6))
    for i, (wrench, q) in enumerate(zip(log[signal],
                                        log["arm.position_measured"],
                                        strict=True)):
        reading.FixValue(context, wrench)
        position.FixValue(context, q)
        result[i] = output.Eval(context)
    return result


def desired_force(scenario, log):
    """F_d,x (N,) over the log: the desired_wrench schedule, else the
    controller's arm_cdmp.F_d."""
    return schedule_values(scenario.task.desired_wrench, log.time,
                           scenario.controller.arm_cdmp.F_d)[:, 0]


def settling(time, force, error):
    """(first contact, settle time) in s, NaN where they do not happen
    (CONTACT_FORCE, SETTLE_BAND, SETTLE_HOLD)."""
    touching = np.flatnonzero(np.abs(force) > CONTACT_FORCE)
    if not len(touching):
        return np.nan, np.nan
    contact = time[touching[0]]
    outside = np.abs(error) > SETTLE_BAND
    for i in np.flatnonzero((time >= contact) & ~outside):
        hold = (time >= time[i]) & (time <= time[i] + SETTLE_HOLD)
        if time[-1] >= time[i] + SETTLE_HOLD and not np.any(outside[hold]):
            return contact, time[i]
    return contact, np.nan


def path_deviation(log):
    """The tool's deviation from its commanded path, in the world: (N, 3)
    position (true minus commanded) and (N,) the angle in rad between the
    true and the commanded orientation. The commanded path starts at the
    true start pose and integrates the reference twist [v; w] held over
    each sample, as the controller reads it (`held_integral`; the turn of
    each sample's w over the time to the next)."""
    pose = log["truth.end_effector_pose"]
    reference = log["reference_velocity"]
    commanded = pose[0, :3] + held_integral(log.time, reference[:, :3])
    R = Rotation.from_matrix([RollPitchYaw(rpy).ToRotationMatrix().matrix()
                              for rpy in pose[:, 3:]])
    turns = Rotation.from_rotvec(reference[:-1, 3:]
                                 * np.diff(log.time)[:, None])
    R_cmd = [R[0]]
    for turn in turns:
        R_cmd.append(turn * R_cmd[-1])
    angle = np.array([(c.inv() * r).magnitude()
                      for c, r in zip(R_cmd, R, strict=True)])
    return pose[:, :3] - commanded, angle, commanded


def _rms(values):
    return float(np.sqrt(np.mean(values**2))) if len(values) else np.nan


def _peak(values):
    return float(np.max(np.abs(values))) if len(values) else np.nan


def run_metrics(scenario, log):
    """The metrics of one run (METRICS, unprefixed)."""
    t = log.time
    F_d = desired_force(scenario, log)
    force = external_wrench(scenario, log)[:, 0]
    error = force - F_d
    truth_error = (external_wrench(scenario, log, "truth.wrist_wrench")[:, 0]
                   - F_d)
    contact, settled = settling(t, force, error)
    after = t >= settled if np.isfinite(settled) else np.zeros(len(t), bool)
    deviation, angle, commanded = path_deviation(log)
    pose = log["truth.end_effector_pose"]
    dist = integrated_deviation(log)[:, :2]
    d_th = scenario.controller.base_cdmp.repulsion.d_th
    person = person_distances(scenario, log)
    close = after & (person <= d_th)
    start = t[close][0] if np.any(close) else np.nan
    before = after & (t < start) if np.isfinite(start) else after
    base = log["truth.base_pose"][:, :2]
    shift = (np.max(np.linalg.norm(base[close] - base[close][0], axis=1))
             if np.any(close) else np.nan)
    return {
        "first_contact_s": float(contact),
        "settle_time_s": float(settled),
        "force_error_mean_N": (float(np.mean(error[after]))
                               if np.any(after) else np.nan),
        "force_error_rms_N": _rms(error[after]),
        "force_error_peak_N": _peak(error[after]),
        "force_error_rms_truth_N": _rms(truth_error[after]),
        "path_deviation_rms_y_m": _rms(deviation[after, 1]),
        "path_deviation_rms_z_m": _rms(deviation[after, 2]),
        "path_deviation_rms_angle_rad": _rms(angle[after]),
        "wipe_stroke_m": (float(np.ptp(pose[after, 1]))
                          if np.any(after) else np.nan),
        "commanded_stroke_m": (float(np.ptp(commanded[after, 1]))
                               if np.any(after) else np.nan),
        "deviation_integral_peak_m": float(np.max(np.abs(dist))),
        "person_min_distance_m": float(np.min(person)),
        "person_close_start_s": float(start),
        "person_close_s": float(np.sum(close) * sample_period(log)),
        "force_error_rms_before_person_N": _rms(error[before]),
        "force_error_rms_person_close_N": _rms(error[close]),
        "force_error_peak_person_close_N": _peak(error[close]),
        "base_shift_person_close_m": float(shift),
        "wall_min_distance_m": float(np.min(static_distances(scenario,
                                                            log))),
    }


def compute_metrics(scenario, logs):
    """METRICS of each run, as `<run>.<metric>`."""
    metrics = {}
    for name, log in logs.items():
        for key, value in run_metrics(scenario, log).items():
            metrics[f"{name}.{key}"] = value
    return metrics


def draw_figures(scenario, logs, folder):
    """Fig. "wipe", one per run (`wiping_<run>.png`): F_x^d and F_x^e, the
    end effector's position, x_dist and y_dist, the base's velocity
    command and the person's distance from the footprint; the time the
    person is within d_th shaded."""
    import matplotlib.pyplot as plt

    d_th = scenario.controller.base_cdmp.repulsion.d_th
    paths = []
    for name, log in logs.items():
        t = log.time
        fig, axes = new_figure(5, title="Wiping: force control along x "
                               f"while wiping along y ({name})")
        axes[0].plot(t, desired_force(scenario, log), "k--", lw=1.0,
                     label="$F_x^d$")
        axes[0].plot(t, external_wrench(scenario, log)[:, 0], lw=0.8,
                     label="$F_x^e$")
        axes[0].set_ylabel("force (N)")
        pose = log["truth.end_effector_pose"]
        _, _, commanded = path_deviation(log)
        for i, axis_name in enumerate("xyz"):
            axes[1].plot(t, pose[:, i] - pose[0, i], label=axis_name)
        axes[1].plot(t, commanded[:, 1] - pose[0, 1], "k--", lw=0.8,
                     label="y commanded")
        axes[1].set_ylabel("$p_{ee}$ - start,\nworld (m)")
        dist = integrated_deviation(log)[:, :2]
        axes[2].plot(t, 1e3 * dist[:, 0], label="$x_{dist}$")
        axes[2].plot(t, 1e3 * dist[:, 1], label="$y_{dist}$")
        axes[2].set_ylabel("deviation,\n$T_b$ (mm)")
        for i, label in enumerate(("$v_x$", "$v_y$", r"$\omega_z$")):
            axes[3].plot(t, log["base.velocity_command"][:, i], label=label)
        axes[3].set_ylabel("$V_b^{ref}$ (m/s, rad/s)")
        person = person_distances(scenario, log)
        axes[4].plot(t, np.where(np.isfinite(person), person, np.nan),
                     label="person")
        axes[4].axhline(d_th, color="r", ls=":", lw=1.0, label="$d_{th}$")
        axes[4].set_ylabel("distance (m)")
        close = person <= d_th
        for axis in axes:
            if np.any(close):
                axis.axvspan(t[close][0], t[close][-1], color="0.9",
                             zorder=0)
            axis.legend(loc="upper right", fontsize=7, ncol=4)
        paths.append(save_figure(fig, folder, f"wiping_{name}"))
        plt.close(fig)
    return paths
