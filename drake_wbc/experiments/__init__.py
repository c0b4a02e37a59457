"""Scenarios and the paper's experiments (Sec. V).

- scenario: a Scenario, one experiment as a YAML file of diagrams/
  (`load_scenario`), checked when it is loaded.
- runner: the controller against the simulated station, one Diagram per
  run (`build_closed_loop`, `simulate`).
- replay: a run's Meshcat replay page.
- reports: `drake-wbc run` (`run_scenario`): runs, metrics, figures.
- common and one module per experiment: metrics and figures.

May import every layer below it (math, robot, stages, controller,
station, hardware); never the analysis, the deployment, the benchmarks,
the stress run or the command line.

The experiments' metrics and figures:

Every module here computes, from the logs of a scenario's runs
(drake_wbc.controller.run_log.RunLog, ground truth included), the metrics of one
experiment and draws the figures that mirror the paper's, through two
functions:

    compute_metrics(scenario, logs) -> dict of numbers
    draw_figures(scenario, logs, folder) -> list of PNG paths

`logs` maps each variant's name to its RunLog. `experiment_module`
returns the module of a scenario's `experiment`; `generic` has the common
metrics only (drake_wbc.experiments.common).
"""

import importlib

MODULES = {
    "generic": "drake_wbc.experiments.common",
    "trajectory_tracking": "drake_wbc.experiments.trajectory_tracking",
    "fixed_point": "drake_wbc.experiments.fixed_point",
    "line_tracking": "drake_wbc.experiments.line_tracking",
    "wiping": "drake_wbc.experiments.wiping",
    "phri": "drake_wbc.experiments.phri",
    "teach": "drake_wbc.experiments.teach",
    "repeat": "drake_wbc.experiments.repeat",
}


def experiment_module(name):
    """The module of the experiment `name` (one of MODULES)."""
    if name not in MODULES:
        raise ValueError(f"experiment = {name!r} is not allowed: must be "
                         f"one of {', '.join(MODULES)}")
    return importlib.import_module(MODULES[name])
