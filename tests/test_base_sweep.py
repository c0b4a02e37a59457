"""The base-model sweep: its points are scenarios (the scenario's own model
among them, giving the scenario's own ratios), and it writes its map."""

import copy
import json

import numpy as np
import pytest

from drake_wbc.analysis import base_sweep
from drake_wbc.analysis.base_sweep import (
    FIRST_ORDER,
    MAPS,
    RIGID,
    RINGING_LAG,
    SweepMap,
    point_scenario,
    run_sweep,
)
from drake_wbc.experiments import trajectory_tracking
from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import (
    find_scenario,
    load_scenario,
    station_base,
)


@pytest.fixture(scope="module")
def shaking():
    return load_scenario(find_scenario("trajectory_tracking_shaking"))


def _base(scenario):
    base = station_base(scenario)
    return (base.lag, base.damping_ratio, *base.acceleration_limits,
            base.servo_time_constant, scenario.station.time_step)


def test_the_scenarios_own_model_is_a_point_of_every_map(shaking):
    loop, compliance, acceleration, wheels = MAPS
    suspension = shaking.station.suspension
    points = [
        point_scenario(shaking, loop, RINGING_LAG, 0.15),
        point_scenario(shaking, compliance, suspension.pitch_frequency,
                       suspension.damping_ratio),
        point_scenario(shaking, acceleration, RINGING_LAG, 5.0),
        point_scenario(shaking, wheels, RIGID, 0.1),
    ]
    for point in points:
        assert _base(point) == _base(shaking)
        assert point.station.suspension == suspension
    default = load_scenario(find_scenario("trajectory_tracking"))
    point = point_scenario(default, loop, 0.2, FIRST_ORDER)
    assert _base(point) == _base(default)
    assert point_scenario(default, compliance, RIGID, 0.1).station.suspension \
        is None


def test_the_wheels_map_varies_the_horizontal_compliance_alone(shaking):
    wheels = MAPS[3]
    compliant = load_scenario(find_scenario("trajectory_tracking_wheels"))
    horizontal = compliant.station.suspension.horizontal
    own = point_scenario(compliant, wheels, horizontal.frequency,
                         horizontal.damping_ratio)
    assert own.station.suspension == compliant.station.suspension
    assert own.station.traction == compliant.station.traction
    point = point_scenario(shaking, wheels, 12.0, 0.05)
    assert point.station.suspension.horizontal.frequency == 12.0
    assert point.station.suspension.horizontal.damping_ratio == 0.05
    point.station.suspension.horizontal = None
    assert point.station.suspension == shaking.station.suspension
    assert _base(point) == _base(shaking)
    # No map of the wheels around a rigid chassis (they are the
    # suspension's).
    default = load_scenario(find_scenario("trajectory_tracking"))
    with pytest.raises(ValueError, match="^station.suspension = None"):
        point_scenario(default, wheels, 8.0, 0.1)


def test_a_short_lag_gets_a_plant_step_of_a_tenth_of_it(shaking):
    point = point_scenario(shaking, MAPS[2], 0.02, 5.0)
    assert point.station.time_step == 0.002
    assert point.station.base.lag == 0.02
    assert point.station.base.servo_time_constant == 0.005


def test_the_sweeps_point_gives_the_scenarios_ratios(shaking, tmp_path):
    scenario = copy.deepcopy(shaking)
    scenario.duration = 2.0
    one = SweepMap("loop", "loop lag (s)", (RINGING_LAG,),
                   "loop damping ratio", (0.15,))
    lines = []
    rows = run_sweep(scenario, tmp_path, maps=(one,), echo=lines.append)
    assert len(rows) == 1 and lines[0].startswith("[ 1/1] loop:")
    logs = {v.name: simulate(build_closed_loop(scenario, v))
            for v in scenario.variants}
    metrics = trajectory_tracking.compute_metrics(scenario, logs)
    for key in base_sweep.RATIOS:
        for prefix in ("", "measured."):
            assert rows[0][prefix + key] == pytest.approx(
                metrics[f"ratio_unfiltered_to_filtered.{prefix}{key}"],
                rel=1e-12)
    assert json.loads((tmp_path / "sweep.json").read_text()) == rows
    assert (tmp_path / "sweep.png").stat().st_size > 10_000
    assert np.isfinite(rows[0]["error_rms_total_m_s"])


def test_a_scenario_of_another_experiment_is_refused(tmp_path):
    with pytest.raises(ValueError, match="^experiment = 'fixed_point'"):
        run_sweep(load_scenario(find_scenario("fixed_point")), tmp_path)
