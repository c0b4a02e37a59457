"""Teaching by hand: a demonstration recorded in pHRI mode and the DMP
learned from it (drake_wbc.math.movement; the paper's future work, Sec. VI,
on its Sec. III-C and IV).

The demonstration of each run is the interval in which S_hri is 1
(demonstration.teaching_interval of the task's phri_switch), from the measured
joints and the base's odometry. Metrics per run, `<run>.<metric>` when
there are several runs:

- start_s, stop_s, duration_s: the demonstration's markers.
- tcp_dx_m, tcp_dy_m, tcp_dz_m, tcp_dyaw_rad: the TCP's net motion;
  tcp_path_m its path length; base_path_m the base's.
- fit_rms_m, fit_yaw_rms_rad: the learned DMP's rollout (dmp.rollout,
  the same duration) against the demonstration, RMS over time of the
  position error and of the yaw error; fit_goal_error_m where it ends.

Figures (`teach_<run>.png`): the TCP's and the base's paths in the plane,
and x, y, z and yaw against normalised time, demonstration against the
learned rollout.
"""

import numpy as np

from drake_wbc.experiments.common import (
    new_figure,
    path_length,
    save_figure,
)
from drake_wbc.experiments.scenario import controller_arm
from drake_wbc.math import movement as mv
from drake_wbc.math.demonstration import (
    demonstration_from_log,
    teaching_interval,
)


def interval(scenario, start=None, stop=None, log=None,
             names=("start", "stop")):
    """(start, stop) of the demonstration: the S_hri markers of the
    scenario's task, each replaced by `start`/`stop` when given; the
    errors call them by `names` (e.g. a command's options).

    Raises:
        ValueError: a given `start` or `stop` that is not a finite
            number, a `stop` not after `start` (the markers'
            included), a given `start` before the first time of `log` (a
            RunLog, when given) or a given `stop` past its last.
    """
    given_start, given_stop = start is not None, stop is not None
    start_name, stop_name = names
    for name, value in ((start_name, start), (stop_name, stop)):
        if value is not None and not np.isfinite(float(value)):
            raise ValueError(f"{name} = {float(value)!r} s is not allowed: "
                             "must be a finite time")
    if start is None or stop is None:
        marked = teaching_interval(
            scenario.task.phri_switch, scenario.duration,
            scenario.controller.phri_switch)
        start = marked[0] if start is None else start
        stop = marked[1] if stop is None else stop
    start, stop = float(start), float(stop)
    if not stop > start:
        raise ValueError(f"{start_name} = {start!r} s, {stop_name} = "
                         f"{stop!r} s is not allowed: the demonstration "
                         "must end after it starts")
    if log is not None and len(log.time):
        first, last = float(log.time[0]), float(log.time[-1])
        if (given_start and start < first - 1e-9) or (
                given_stop and stop > last + 1e-9):
            raise ValueError(
                f"{start_name} = {start!r} s, {stop_name} = {stop!r} s is "
                "not allowed: must be an interval of the log (from "
                f"{first:.3f} to {last:.3f} s)")
    return start, stop


def learn_from_log(scenario, log, start=None, stop=None, num_basis=None,
                   source="", names=("start", "stop")):
    """The LearnedMovement of the demonstration in `log` (a RunLog),
    learned with the gains of the scenario's whole-body DMP (so that it
    replays with the same attractor); `interval` takes start, stop and
    names."""
    start, stop = interval(scenario, start, stop, log, names)
    demo = demonstration_from_log(log, start, stop,
                                  controller_arm(scenario))
    dmp = scenario.controller.whole_body_cdmp.dmp
    params = mv.dmp.DmpParameters(
        alpha_z=dmp.alpha_z, beta_z=dmp.beta_z, tau=1.0,
        num_basis=mv.DEFAULT_NUM_BASIS if num_basis is None else num_basis)
    return mv.learn_movement(demo, params, source=source)


def fit_metrics(movement):
    """The learned rollout against the (first) demonstration."""
    demo = movement.demonstrations[0]
    t, y, _ = movement.rollout(dt=0.005, extra_time=0.0)
    u = demo.time - demo.time[0]
    rolled = np.column_stack([np.interp(u, t, y[:, i]) for i in range(4)])
    error = rolled - demo.tcp
    return {
        "fit_rms_m": float(np.sqrt(np.mean(np.sum(error[:, :3]**2,
                                                  axis=1)))),
        "fit_yaw_rms_rad": float(np.sqrt(np.mean(error[:, 3]**2))),
        "fit_goal_error_m": float(np.linalg.norm(y[-1, :3]
                                                 - movement.goal[:3])),
    }


def movement_metrics(movement, start, stop):
    """The metrics of the module's docstring for one learned movement."""
    demo = movement.demonstrations[0]
    delta = demo.tcp[-1] - demo.tcp[0]
    metrics = {
        "start_s": start, "stop_s": stop, "duration_s": demo.duration,
        "tcp_dx_m": float(delta[0]), "tcp_dy_m": float(delta[1]),
        "tcp_dz_m": float(delta[2]), "tcp_dyaw_rad": float(delta[3]),
        "tcp_path_m": path_length(demo.tcp[:, :3]),
        "base_path_m": (path_length(demo.base[:, :2]) if demo.base is not None
                        else float("nan")),
    }
    metrics.update(fit_metrics(movement))
    return metrics


def recorded(scenario, log):
    """Whether `log` (a RunLog of `scenario`) holds enough of the
    demonstration to learn it (3 samples): a run cut short (`drake-wbc
    run teach --duration 0.5`) may end before the demonstration starts."""
    start, stop = teaching_interval(
        scenario.task.phri_switch, scenario.duration,
        scenario.controller.phri_switch)
    inside = (log.time >= start - 1e-9) & (log.time <= stop + 1e-9)
    return bool(stop > start and np.count_nonzero(inside) >= 3)


def compute_metrics(scenario, logs):
    """The metrics of the module's docstring, of each run; of a run that
    ended before it recorded the demonstration (`recorded`), the
    markers' start_s alone."""
    metrics = {}
    for name, log in logs.items():
        if recorded(scenario, log):
            start, stop = interval(scenario)
            values = movement_metrics(learn_from_log(scenario, log), start,
                                      stop)
        else:
            values = {"start_s": teaching_interval(
                scenario.task.phri_switch, np.inf,
                scenario.controller.phri_switch)[0]}
        prefix = "" if len(logs) == 1 else f"{name}."
        metrics.update({prefix + k: v for k, v in values.items()})
    return metrics


def draw_movement(movement, folder, name, title=None):
    """`<name>.png`: the demonstrations against the learned rollout."""
    import matplotlib.pyplot as plt

    t, y, _ = movement.rollout(dt=0.01, extra_time=0.0)
    u = t / movement.params.duration
    fig, axes = new_figure(4, title=title or f"teach: {name}", width=11.0)
    fig.set_size_inches(11.0, 8.0)
    for axis in axes:
        axis.remove()
    grid = fig.add_gridspec(4, 2)
    plane = fig.add_subplot(grid[:, 0])
    for k, demo in enumerate(movement.demonstrations):
        label = "demonstration" if k == 0 else None
        plane.plot(demo.tcp[:, 0], demo.tcp[:, 1], "C0", label=label)
        if demo.base is not None:
            plane.plot(demo.base[:, 0], demo.base[:, 1], "C2",
                       label="base (demonstration)" if k == 0 else None)
    plane.plot(y[:, 0], y[:, 1], "C1--", label="learned rollout")
    plane.plot(*movement.start[:2], "ko", label="start")
    plane.plot(*movement.goal[:2], "k*", markersize=10, label="goal")
    plane.set_aspect("equal")
    plane.grid(True, alpha=0.3)
    plane.set_xlabel("x (m)")
    plane.set_ylabel("y (m)")
    plane.legend(fontsize=7, loc="best")
    units = ("x (m)", "y (m)", "z (m)", "yaw (rad)")
    for i, label in enumerate(units):
        axis = fig.add_subplot(grid[i, 1])
        for demo in movement.demonstrations:
            axis.plot((demo.time - demo.time[0]) / demo.duration,
                      demo.tcp[:, i], "C0")
        axis.plot(u, y[:, i], "C1--")
        axis.set_ylabel(label)
        axis.grid(True, alpha=0.3)
    axis.set_xlabel("normalised time")
    path = save_figure(fig, folder, name)
    plt.close(fig)
    return path


def draw_figures(scenario, logs, folder):
    """`teach_<run>.png` of each run that recorded the demonstration
    (module docstring)."""
    return [draw_movement(learn_from_log(scenario, log), folder,
                          f"teach_{name}", f"teach: demonstration against "
                          f"the learned DMP ({name})")
            for name, log in logs.items() if recorded(scenario, log)]
