"""`drake-wbc plot`: the metrics and figures of a run from its LCM log.

`plot_lcm_log` reads the log (drake_wbc.deployment.lcm_logs), then writes
into the output folder what `drake-wbc run` writes for a simulated run
(drake_wbc.experiments.reports) as far as the logged signals allow:

- `log_<run>.npz` and `.csv`: the signals on the controller's clock;
- the experiment's figures and metrics (drake_wbc.experiments), when the
  log has the signals they need (ground truth comes from a simulated
  robot only; a real robot's log gets the figures below alone);
- `hardware.png`: the commands as sent, the robot's status and the
  interface's diagnostics (watchdog stops, stream ages, rejected
  messages);
- `summary.json`.
"""

from pathlib import Path

import numpy as np

from drake_wbc.deployment.lcm_logs import read_lcm_log
from drake_wbc.experiments import experiment_module
from drake_wbc.experiments.common import new_figure, run_metrics, save_figure
from drake_wbc.experiments.reports import json_text, plain_values
from drake_wbc.experiments.scenario import (
    Scenario,
    find_scenario,
    load_scenario,
    scenario_robot,
)
from drake_wbc.hardware.interface import DIAGNOSTICS
from drake_wbc.hardware.options import HardwareOptions


def plot_lcm_log(logfile, output, scenario=None, variant=None,
                 deployment=0):
    """Writes the log, metrics and figures of the LCM log `logfile`.

    Args:
        logfile: an LCM log file.
        output: the folder to write into (created).
        scenario: the Scenario that ran, or its name or file (None: a
            generic one: overview figures, common metrics).
        variant: the name of the run that was deployed (the scenario's
            first if None).
        deployment: which deployment in the log (0: the first; see
            lcm_logs.read_lcm_log).

    Returns:
        dict: the summary, as written to summary.json (with `skipped`:
        what the log's signals did not allow, and why).
    """
    name = Path(logfile).stem
    if scenario is None:
        scenario = Scenario(description=f"LCM log {name}")
    elif not isinstance(scenario, Scenario):
        path = find_scenario(scenario)
        name, scenario = path.stem, load_scenario(path)
    run = variant or scenario.variants[0].name
    if run not in [v.name for v in scenario.variants]:
        names = ", ".join(v.name for v in scenario.variants)
        raise ValueError(f"variant = {run!r} is not allowed: must be one of "
                         f"{names}")
    log = read_lcm_log(logfile, scenario.hardware or HardwareOptions(),
                       deployment)
    robot = scenario_robot(scenario)
    if "arm.position_measured" in log and (
            log["arm.position_measured"].shape[1] != len(robot.arm.joints)):
        raise ValueError(
            f"scenario = {name!r} is not allowed for this log: its robot "
            f"{robot.name}'s arm has {len(robot.arm.joints)} joints, the "
            f"log's {log['arm.position_measured'].shape[1]}; give the robot "
            "that ran (drake-wbc plot --robot FILE)")
    output = Path(output)
    output.mkdir(parents=True, exist_ok=True)
    saved = log.save(output / f"log_{run}")
    files = [saved, saved.with_suffix(".csv")]
    summary = {"scenario": name, "description": scenario.description,
               "experiment": scenario.experiment, "logfile": str(logfile),
               "duration_s": float(log.time[-1]) if len(log.time) else 0.0,
               "signals": sorted(log.signals), "skipped": {}}
    module = experiment_module(scenario.experiment)
    logs = {run: log}
    for key, compute in (
            ("runs", lambda: {run: run_metrics(scenario, log)}),
            ("metrics", lambda: module.compute_metrics(scenario, logs)),
            ("figures", lambda: module.draw_figures(scenario, logs, output))):
        try:
            value = compute()
        except KeyError as error:
            summary["skipped"][key] = f"the log has no signal {error}"
            continue
        if key == "figures":
            files += value
        else:
            summary[key] = plain_values(value)
    files.append(draw_hardware_figure(log, output, title=name))
    summary["files"] = [Path(f).name for f in files]
    (output / "summary.json").write_text(json_text(summary))
    return summary


def draw_hardware_figure(log, folder, title=""):
    """The commands as sent, the status received and the interface's
    diagnostics over time; the panels whose signals the log lacks are
    left empty. Returns the PNG's path."""
    import matplotlib.pyplot as plt

    fig, axes = new_figure(5, title=f"LCM run {title}".strip())
    panels = (
        ("base.velocity_command", "$V_b$ sent", ("vx", "vy", "wz")),
        ("arm.position_command", "$q$ sent (rad)", None),
        ("base.state_estimated", "base state", ("x", "y", "yaw")),
    )
    for axis, (signal, label, legend) in zip(axes, panels, strict=False):
        axis.set_ylabel(label)
        if signal in log:
            values = log[signal]
            axis.plot(log.time, values[:, :len(legend)] if legend
                      else values)
            if legend:
                axis.legend(legend, loc="upper right", fontsize=7)
    axes[3].set_ylabel("status age (s)")
    axes[4].set_ylabel("watchdog, rejected")
    if "hardware.diagnostics" in log:
        values = log["hardware.diagnostics"]
        column = {name: i for i, name in enumerate(DIAGNOSTICS)}
        for name in ("base_state_age", "arm_status_age", "wrist_wrench_age",
                     "obstacle_points_age"):
            axes[3].plot(log.time, np.minimum(values[:, column[name]], 1.0),
                         label=name)
        for name in DIAGNOSTICS:
            if name in ("watchdog_tripped", "base_stopped") or name.endswith(
                    "_rejected"):
                axes[4].step(log.time, values[:, column[name]], where="post",
                             label=name)
        for axis in axes[3:]:
            axis.legend(loc="upper right", fontsize=7)
    path = save_figure(fig, folder, "hardware")
    plt.close(fig)
    return path

