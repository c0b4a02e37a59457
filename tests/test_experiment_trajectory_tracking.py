"""Experiment 1 (trajectory tracking) run end to end: the base filter
smooths the base's command and removes the error of the base's slow
response, which the arm compensates."""

import json

import numpy as np
import pytest

from drake_wbc.experiments import trajectory_tracking
from drake_wbc.experiments.reports import run_scenario
from drake_wbc.experiments.scenario import (
    controller_for,
    find_scenario,
    load_scenario,
)


@pytest.fixture(scope="module")
def summary(tmp_path_factory):
    scenario = load_scenario(find_scenario("trajectory_tracking"))
    scenario.duration = 3.0  # the step (1.0 to 2.5 s) and 0.5 s after it
    folder = tmp_path_factory.mktemp("trajectory_tracking")
    result = run_scenario(scenario, folder, name="trajectory_tracking",
                          replay=False, progress=False, echo=None)
    result["folder"] = folder
    result["scenario"] = scenario
    return result


def test_the_filter_smooths_the_base_command(summary):
    # Eq. (filtering) with zeta = 1 has a step response of slope at most
    # omega_f / e per unit step; the bypassed filter passes the step, which
    # the base's acceleration limit then ramps over a few ticks.
    scenario, logs = summary["scenario"], summary["logs"]
    h = scenario.controller.time_step
    omega_f = scenario.controller.base_filter.omega_f
    step = 0.05  # half of the 0.1 m/s step goes to the base
    filtered = np.diff(logs["filtered"]["base.velocity_command"][:, 0])
    unfiltered = np.diff(logs["unfiltered"]["base.velocity_command"][:, 0])
    assert np.max(np.abs(filtered)) <= step * omega_f / np.e * h * 1.01
    a_max = controller_for(scenario).safety.base_acceleration_limits[0]
    assert np.max(np.abs(unfiltered)) == pytest.approx(a_max * h, rel=1e-6)
    assert np.max(logs["unfiltered"]["base.velocity_command"][:, 0]) == (
        pytest.approx(step, rel=1e-6))


def test_the_filter_removes_the_error_of_the_slow_base(summary):
    metrics = summary["metrics"]
    ratio = metrics[
        "ratio_unfiltered_to_filtered.error_rms_base_band_m_s"]
    assert ratio > 1.5
    # Both runs track the step once it has settled.
    for run in ("filtered", "unfiltered"):
        log = summary["logs"][run]
        late = (log.time > 2.2) & (log.time < 2.5)
        v = log["truth.end_effector_velocity"][late, 0]
        assert np.mean(v) == pytest.approx(0.1, abs=0.01)


def test_outputs_are_written(summary):
    folder = summary["folder"]
    written = json.loads((folder / "summary.json").read_text())
    assert written["experiment"] == "trajectory_tracking"
    for key in ("filtered.error_rms_base_band_m_s",
                "unfiltered.oscillation_rms_mount_band_m_s",
                "ratio_unfiltered_to_filtered.error_rms_base_band_m_s"):
        assert np.isfinite(written["metrics"][key])
    assert (folder / "trajectory_tracking.png").stat().st_size > 10_000
    for run in ("filtered", "unfiltered"):
        assert written["runs"][run]["all_finite"]
        assert (folder / f"log_{run}.csv").is_file()
        data = np.load(folder / f"log_{run}.npz")
        assert data["truth.end_effector_velocity"].shape[1] == 6


def test_step_window_needs_a_step():
    scenario = load_scenario(text="task: {reference_velocity: {times: [0], "
                                  "values: [[0, 0, 0, 0, 0, 0]]}}")
    with pytest.raises(ValueError, match="no step along x"):
        trajectory_tracking.step_window(scenario)
