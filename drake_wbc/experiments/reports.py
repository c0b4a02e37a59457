"""`drake-wbc run`: one scenario, simulated, measured and written out.

For each of the scenario's runs (variants) `run_scenario` simulates the
closed loop (drake_wbc.experiments.runner) with a progress line, and writes
into the
output folder:

- `log_<run>.npz` and `log_<run>.csv`: every logged signal with a header;
- `replay_<run>.html`: the Meshcat replay, one self-contained page;
- the experiment's figures (PNG) mirroring the paper's;
- `summary.json`: the metrics, of each run and of the experiment.

The summary is also printed.
"""

import copy
import json
import math
from pathlib import Path

import numpy as np

from drake_wbc.experiments import experiment_module
from drake_wbc.experiments.common import run_metrics
from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import (
    Scenario,
    find_scenario,
    load_scenario,
)


def run_scenario(scenario, output, name=None, duration=None, replay=None,
                 progress=True, echo=print):
    """Runs every variant of `scenario` and writes the outputs.

    Args:
        scenario: a Scenario, or a scenario's name or file.
        output: the folder to write into (created).
        name: the scenario's name in the summary (the file's stem when
            given by name or file).
        duration: simulated time in s (the scenario's if None).
        replay: write the replay pages (the scenario's outputs.replay if
            None).
        progress: show the progress line.
        echo: where the summary is printed (None: nowhere).

    Returns:
        dict: the summary (as written to summary.json), with the RunLogs
        under the key "logs" (not written).
    """
    if not isinstance(scenario, Scenario):
        path = find_scenario(scenario)
        name = name or path.stem
        scenario = load_scenario(path)
    name = name or "scenario"
    output = Path(output)
    output.mkdir(parents=True, exist_ok=True)
    replay = scenario.outputs.replay if replay is None else replay
    if duration is not None:
        # The metrics and figures read the run's length off the scenario.
        scenario = copy.copy(scenario)
        scenario.duration = duration
    duration = scenario.duration
    logs, files = {}, []
    for variant in scenario.variants:
        loop = build_closed_loop(scenario, variant, replay=replay)
        log = simulate(loop, duration=duration, progress=progress)
        logs[variant.name] = log
        saved = log.save(output / f"log_{variant.name}")
        files += [saved, saved.with_suffix(".csv")]
        if loop.recorder is not None:
            tcp = log["truth.end_effector_pose"][:, :3]
            loop.recorder.add_path("end_effector", tcp)
            files.append(loop.recorder.write(
                output / f"replay_{variant.name}.html"))
    module = experiment_module(scenario.experiment)
    summary = {
        "scenario": name,
        "description": scenario.description,
        "experiment": scenario.experiment,
        "runs": {k: run_metrics(scenario, log) for k, log in logs.items()},
        "metrics": plain_values(module.compute_metrics(scenario, logs)),
    }
    if scenario.outputs.plots:
        files += module.draw_figures(scenario, logs, output)
    summary["files"] = [str(Path(f).name) for f in files]
    (output / "summary.json").write_text(json_text(summary))
    if echo is not None:
        echo(format_summary(summary, output))
    summary["logs"] = logs
    return summary


def short_run_note(scenario, duration=None):
    """A sentence on the metrics that a run of `scenario` for `duration`
    s (its own if None) will leave NaN because it is too short to
    measure them (the experiment's `short_run_note`), or None."""
    module = experiment_module(scenario.experiment)
    note = getattr(module, "short_run_note", None)
    if note is None:
        return None
    if duration is not None:
        scenario = copy.copy(scenario)
        scenario.duration = duration
    return note(scenario)


def plain_values(value):
    """`value` with numpy scalars and arrays as plain Python, for JSON."""
    if isinstance(value, dict):
        return {str(k): plain_values(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [plain_values(v) for v in value]
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    return value


def json_text(value, indent=2):
    """`value` (plain_values of it) as strict JSON text, with NaN and
    +-inf, for which JSON has no number (and strict readers, jq's and
    most languages', refuse Python's NaN), as the strings "nan", "inf"
    and "-inf", which float() reads back."""
    return json.dumps(_strict(plain_values(value)), indent=indent,
                      allow_nan=False)


def from_json_text(text):
    """The plain data of JSON `text` written by `json_text`, its strings
    "nan", "inf" and "-inf" read back as the floats they stand for.

    Raises:
        ValueError: for text that is not JSON.
    """
    return _mapped(json.loads(text), _NON_FINITE.get)


_NON_FINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}
"""The strings `json_text` writes for the floats JSON has no number for."""


def _strict(value):
    """`value` (plain data) with its non-finite floats as strings."""
    return _mapped(value, lambda v: str(v) if isinstance(v, float)
                   and not math.isfinite(v) else None)


def _mapped(value, leaf):
    """`value` (plain data) with each leaf v for which leaf(v) is not None
    replaced by it (through mappings and lists)."""
    if isinstance(value, dict):
        return {k: _mapped(v, leaf) for k, v in value.items()}
    if isinstance(value, list):
        return [_mapped(v, leaf) for v in value]
    if isinstance(value, (str, float)):
        replaced = leaf(value)
        if replaced is not None:
            return replaced
    return value


def format_summary(summary, output):
    """The summary as text: the experiment's metrics, then each run's
    (headed by its name when there are several), then the files."""
    lines = [f"{summary['scenario']}: {summary['description']}", ""]
    if summary["metrics"]:
        lines.append("Experiment metrics:")
        lines += [f"  {k:44s} {_shown(v)}"
                  for k, v in summary["metrics"].items()]
        lines.append("")
    for run, metrics in summary["runs"].items():
        lines.append("Run metrics:" if len(summary["runs"]) == 1
                     else f"Run {run}:")
        lines += [f"  {k:44s} {_shown(v)}" for k, v in metrics.items()]
        lines.append("")
    lines.append(f"Written to {output}/: " + ", ".join(summary["files"])
                 + ", summary.json")
    return "\n".join(lines)


def _shown(value):
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)
