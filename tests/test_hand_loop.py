"""The pHRI loop's stability in simulation, with the hand of the `phri`
scenario given an impedance (drake_wbc.station.hand): at the paper's
k_hri = 0.05 the admittance buzzes at the control rate, held only by the
arm's acceleration limit; at k_hri = 0.01 it does not (README, pHRI).
Short runs: the first push of stage A."""

import numpy as np
import pytest

from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.station.scene import HandImpedance

DURATION = 2.5
"""s: the first push of stage A (2 N back from 0.5 s)."""


def alternating(u):
    """RMS of the sign-alternating part (u[k+1] - 2 u[k] + u[k-1]) / 4 of
    each column of u (N, k)."""
    return np.sqrt(np.mean(((u[2:] - 2 * u[1:-1] + u[:-2]) / 4) ** 2,
                           axis=0))


@pytest.fixture(scope="module")
def runs():
    out = {}
    for k_hri in (0.05, 0.01):
        scenario = load_scenario(find_scenario("phri"))
        scenario.scene.hand.impedance = HandImpedance()
        scenario.controller.whole_body_cdmp.k_hri = k_hri
        log = simulate(build_closed_loop(scenario), DURATION)
        out[k_hri] = log
    return out


def test_above_the_limit_the_admittance_buzzes_and_below_it_does_not(runs):
    fast, slow = runs[0.05], runs[0.01]
    after = fast.time > 0.5
    buzz = alternating(fast["arm_velocity_command"][after, :3])
    calm = alternating(slow["arm_velocity_command"][after, :3])
    limited_fast = np.mean(fast["arm_limited"][after, 0] > 0.5)
    limited_slow = np.mean(slow["arm_limited"][after, 0] > 0.5)
    assert np.max(buzz) > 10e-3  # m/s: centimetres per second at 50 Hz
    assert np.max(calm) < 2e-3  # the sensor's noise times k_hri
    assert limited_fast > 0.3
    assert limited_slow < 0.05


def test_the_hand_still_pushes_the_tool_back(runs):
    """Both follow the scheduled push of -2 N in x: the tool moves back,
    five times as far at the five times larger gain, roughly."""
    moved = {k: log["truth.end_effector_pose"][-1, 0]
             - log["truth.end_effector_pose"][0, 0]
             for k, log in runs.items()}
    assert moved[0.01] < -0.003
    assert moved[0.05] < 3 * moved[0.01]
