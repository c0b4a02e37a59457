"""The pHRI admittance loop's linear model (drake_wbc.analysis.
admittance_loop): its plant part against a closed form, checked on the
nonlinear plant part simulated in double."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from drake_wbc.analysis import admittance_loop as al
from drake_wbc.analysis.frequency import frequency_response
from drake_wbc.experiments.scenario import find_scenario, load_scenario

PERIOD = 0.01
STEP = np.array([0.0, -0.0155, -0.0219, 0.0, 0.0069, 0.0])
"""rad: a small arm command that moves the tool about 5 mm forward."""


@pytest.fixture(scope="module")
def setting():
    scenario = load_scenario(find_scenario("phri"))
    station = al._station(scenario)
    return scenario, station


def test_the_hand_spring_reads_minus_k_times_the_tool_displacement(setting):
    """At low frequency the sensor reads what the hand's spring pushes
    back with: -K dx of the tool centre point's displacement dx (the hand
    mass and the damper do not act at rest), in the world's axes, here
    from the linearised plant part, dx from a simulation of the
    nonlinear one."""
    scenario, station = setting
    hand = al.HandImpedance()
    diagram, plant, model = al.build_plant_part(station, hand)
    context = al.plant_part_context(station, diagram, plant, model)
    mine = plant.GetMyContextFromRoot(context)
    p0 = model.tcp_frame.CalcPoseInWorld(mine).translation().copy()
    q0 = np.asarray(scenario.station.initial_arm_positions, dtype=float)
    diagram.GetInputPort("arm.position_command").FixValue(context, q0 + STEP)
    simulator = Simulator(diagram, context)
    simulator.AdvanceTo(2.0)
    after = plant.GetMyContextFromRoot(simulator.get_context())
    dx = model.tcp_frame.CalcPoseInWorld(after).translation() - p0
    R_WM = model.ft_measurement_frame.CalcPoseInWorld(after).rotation(
    ).matrix()
    linear, _ = al.linearize_plant_part(station, hand, PERIOD)
    H = frequency_response(linear.A(), linear.B(), linear.C(), linear.D(),
                           [2 * np.pi * 0.02], PERIOD)[0]
    reading = R_WM @ (H[:3] @ STEP).real
    assert np.linalg.norm(dx) > 3e-3
    np.testing.assert_allclose(reading, -hand.stiffness * dx,
                               atol=0.05 * hand.stiffness
                               * np.linalg.norm(dx))
