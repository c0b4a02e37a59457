"""Experiment 2 (paper Sec. V, Fig. "wbc_avoid"): diagrams/fixed_point.yaml
and drake_wbc.experiments.fixed_point.

One simulation for the module: the scenario's first DURATION seconds, the
first approach (from the left, 1.5 to 9 s) and the second up to the
switch of k_n (C_m in the band from about 19.5 s, s_c = 1 throughout).
"""

import math

import numpy as np
import pytest

from drake_wbc.controller.task import Schedule
from drake_wbc.experiments import experiment_module, fixed_point
from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import (
    controller_for,
    find_scenario,
    load_scenario,
)

DURATION = 21.5
"""s: up to the start of k_n's ramp (21.5 to 22.5 s in the scenario)."""

MIN_PERSON_DISTANCE = 0.25
"""m: the base keeps at least this far from the person (half of d_th);
0.36 m measured in the first approach."""

MIN_AVOIDANCE = 0.03
"""m: the base gives way by at least this much in the first approach
(about 6 cm measured)."""

MAX_EE_DEVIATION = 0.02
"""m: the end effector stays within this of its start (ground truth)
during and after the first approach. What is left is the base's 0.2 s
velocity loop, which the compensation does not see: about 1 cm measured."""

CAPABILITY_TOLERANCE = 0.002
"""C_m may end this far below C_m^l with s_c = 1: the compensation keeps
C_m constant to first order, and the tracking-error elimination moves the
arm a little along the gradient (0.0338 measured for C_m^l = 0.035)."""

DOCUMENTED_KEYS = (
    "approaches", "max_ee_deviation_m", "final_ee_deviation_m",
    "max_base_displacement_m", "min_person_distance_m",
    "min_capability_compensation_on", "min_capability_compensation_off",
    "capability_band_lower", "capability_band_upper",
    "max_integrated_deviation_m")
APPROACH_KEYS = (
    "start_s", "end_s", "compensation_switch", "min_person_distance_m",
    "max_ee_deviation_close_m", "max_ee_deviation_after_m",
    "min_capability")


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(find_scenario("fixed_point"))


@pytest.fixture(scope="module")
def log(scenario):
    return simulate(build_closed_loop(scenario), duration=DURATION)


@pytest.fixture(scope="module")
def metrics(scenario, log):
    return fixed_point.compute_metrics(scenario, {"run": log})


def test_scenario_is_the_papers_setting(scenario):
    assert experiment_module(scenario.experiment) is fixed_point
    assert scenario.controller.base_cdmp.repulsion.d_th == 0.5
    band = controller_for(scenario).capability_band
    assert (band.lower, band.upper) == (0.035, 0.04)
    assert not np.any(scenario.task.reference_velocity.values)
    times = np.array([0.0, 21.0, 22.0, 23.0, 35.0, 36.0])
    k_n = fixed_point.schedule_values(scenario.task.null_space_gain, times,
                                      0.0)[:, 0]
    np.testing.assert_allclose(k_n, [0.0, 0.0, 0.05, 0.1, 0.1, 0.1])
    s_c = fixed_point.schedule_values(scenario.task.compensation_switch,
                                      times, 1.0)[:, 0]
    np.testing.assert_array_equal(s_c, [1, 1, 1, 1, 1, 0])


def test_schedule_values_hold_linear_and_default():
    hold = Schedule(times=[1.0, 2.0], values=[[3.0], [5.0]])
    np.testing.assert_array_equal(
        fixed_point.schedule_values(hold, [0.0, 1.5, 2.0, 9.0], 0.0)[:, 0],
        [3.0, 3.0, 5.0, 5.0])
    linear = Schedule(times=[1.0, 2.0], values=[[3.0], [5.0]],
                      interpolation="linear")
    np.testing.assert_allclose(
        fixed_point.schedule_values(linear, [0.0, 1.5, 9.0], 0.0)[:, 0],
        [3.0, 4.0, 5.0])
    np.testing.assert_array_equal(
        fixed_point.schedule_values(Schedule(), [0.0, 1.0], 0.7),
        [[0.7], [0.7]])


def test_approach_intervals_merge_short_gaps():
    time = np.arange(0.0, 10.0, 0.1)
    distance = np.full(time.size, 1.0)
    distance[10:20] = 0.3      # 1.0 to 1.9 s
    distance[22:30] = 0.3      # 0.3 s later: the same approach
    distance[60:70] = 0.3      # 6.0 to 6.9 s
    assert fixed_point.approach_intervals(time, distance, 0.5) == [
        (10, 30), (60, 70)]


def test_first_approach_base_avoids_and_end_effector_stays_put(log,
                                                               metrics):
    assert metrics["approach_1_compensation_switch"] == 1.0
    assert metrics["approach_1_min_person_distance_m"] > MIN_PERSON_DISTANCE
    start = np.searchsorted(log.time, metrics["approach_1_start_s"])
    end = np.searchsorted(log.time, metrics["approach_1_end_s"])
    base = log["truth.base_pose"][:, :2]
    assert np.max(np.linalg.norm(base[start:end] - base[0], axis=1)) > \
        MIN_AVOIDANCE
    assert metrics["approach_1_max_ee_deviation_close_m"] < MAX_EE_DEVIATION
    assert metrics["approach_1_max_ee_deviation_after_m"] < MAX_EE_DEVIATION


def test_robust_compensation_holds_capability_at_the_band(metrics):
    lower = metrics["capability_band_lower"]
    assert metrics["approaches"] == 2
    # The second approach drives C_m into the band ...
    assert metrics["approach_2_min_capability"] < \
        metrics["capability_band_upper"]
    # ... and the robust compensation stops it at the lower limit.
    assert metrics["min_capability_compensation_on"] >= \
        lower - CAPABILITY_TOLERANCE
    # s_c is 1 all through: no C_m with it off (NaN, as documented).
    assert math.isnan(metrics["min_capability_compensation_off"])
    assert metrics["min_person_distance_m"] > MIN_PERSON_DISTANCE


def test_metrics_have_the_documented_keys(metrics):
    for key in DOCUMENTED_KEYS:
        assert key in metrics
    for k in (1, 2):
        for key in APPROACH_KEYS:
            assert f"approach_{k}_{key}" in metrics
    # The person is still close when the shortened run ends.
    assert math.isnan(metrics["approach_2_max_ee_deviation_after_m"])


def test_metrics_of_several_runs_are_prefixed(scenario, log):
    metrics = fixed_point.compute_metrics(scenario, {"a": log, "b": log})
    assert metrics["a.approaches"] == metrics["b.approaches"] == 2


def test_figure_is_written(scenario, log, tmp_path):
    paths = fixed_point.draw_figures(scenario, {"run": log}, tmp_path)
    assert [p.name for p in paths] == ["wbc_avoid_run.png"]
    assert paths[0].read_bytes().startswith(b"\x89PNG")


# The test arm is untuned (k_j caps its P_jnt): said, and not the point.
@pytest.mark.filterwarnings(
    "ignore::drake_wbc.robot.tuning.RobotTuningWarning")
def test_a_stretch_without_samples_is_nan_in_the_summary(tmp_path, capsys):
    """`drake-wbc run fixed_point --robot <a 7-joint arm> --duration 3`:
    the person is still close when the run ends, and s_c is never 0, so
    two metrics measure an empty stretch. summary.json wrote them as
    null; like every metric that is not a number they are "nan" (README),
    read back as NaN."""
    from omni_arm import write_omni_arm

    from drake_wbc.cli.main import main
    from drake_wbc.experiments.reports import from_json_text

    robot = write_omni_arm(tmp_path, 7)
    output = tmp_path / "out"
    assert main(["run", "fixed_point", "--robot", str(robot), "--duration",
                 "3", "--output", str(output)]) == 0
    text = (output / "summary.json").read_text()
    assert "null" not in text
    metrics = from_json_text(text)["metrics"]
    assert metrics["approaches"] == 1
    assert metrics["approach_1_end_s"] == 3.0
    for key in ("approach_1_max_ee_deviation_after_m",
                "min_capability_compensation_off"):
        assert math.isnan(metrics[key])
    assert metrics["min_capability_compensation_on"] == \
        metrics["approach_1_min_capability"]
