"""The hand with impedance (drake_wbc.station.hand): its parameters
checked where they enter, the push at rest equal to the schedule's, the
spring law of a tool moved by the arm against a hand that stays, and a
scene without it unchanged."""

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_typed
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_wbc.station.scene import HandForce, HandImpedance, Scene
from drake_wbc.station.simulation import SimulatedStation, StationOptions


@pytest.mark.parametrize("field, value", [
    ("stiffness", 0.0), ("stiffness", float("inf")), ("damping", -1.0),
    ("mass", 0.0), ("reaction_time", 0.0)])
def test_the_impedance_is_checked_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        HandImpedance(**{field: value})


def test_the_impedance_comes_from_yaml_and_needs_a_schedule():
    hand = yaml_load_typed(schema=HandForce, data="""
        times: [0, 1]
        forces: [[0, 0, 0], [1, 0, 0]]
        impedance: {stiffness: 800, damping: 25}
    """)
    assert hand.impedance.stiffness == 800.0
    assert hand.impedance.mass == HandImpedance().mass
    with pytest.raises(ValueError, match="impedance"):
        HandForce(impedance=HandImpedance())


ARM_MOVE_TIME = 0.5
"""s: how long the arm takes to its offset (a cubic from rest to rest,
within its speed and acceleration limits: its servo refuses a step)."""


def run_station(hand, arm_offset=None, until=(1.5,)):
    """The station (5 ms) holding its arm at the initial positions plus
    `arm_offset` (moved there in ARM_MOVE_TIME), the base still; [(hand
    force, TCP position)] at the times `until`, and the TCP's position at
    the start."""
    options = StationOptions(time_step=0.005)
    station = SimulatedStation(options, Scene(hand=hand))
    builder = DiagramBuilder()
    diagram = builder.AddSystem(station.diagram)
    q = np.asarray(station.options.initial_arm_positions, dtype=float)
    offset = np.zeros(q.size) if arm_offset is None else arm_offset
    move = PiecewisePolynomial.CubicHermite(
        [0.0, ARM_MOVE_TIME], np.column_stack([q, q + offset]),
        np.zeros((q.size, 2)))
    for name, source in (
            ("base.velocity_command", ConstantVectorSource(np.zeros(3))),
            ("arm.position_command", TrajectorySource(move))):
        builder.Connect(builder.AddSystem(source).get_output_port(),
                        diagram.GetInputPort(name))
    simulator = Simulator(builder.Build())
    root = simulator.get_mutable_context()
    station.set_initial_state(root)
    simulator.Initialize()
    context = diagram.GetMyContextFromRoot(root)

    def read():
        return (diagram.GetOutputPort("truth.hand_force").Eval(context)
                .copy(), diagram.GetOutputPort("truth.end_effector_pose")
                .Eval(context)[:3].copy())

    start = read()[1]
    samples = []
    for t in until:
        simulator.AdvanceTo(t)
        samples.append(read())
    return samples, start, station


def test_at_rest_the_hand_pushes_with_the_scheduled_force():
    """However stiff the grip, once the person's intention has caught up
    with the tool (a few reaction times) the push is the schedule's: the
    spring's offset is force / stiffness."""
    push = [2.0, -3.0, 1.5]
    for stiffness in (150.0, 1500.0):
        hand = HandForce(times=[0.0, 0.2, 5.0],
                         forces=[[0, 0, 0], push, push],
                         impedance=HandImpedance(stiffness=stiffness,
                                                 damping=20.0))
        [(force, _)], _, station = run_station(hand, until=(2.0,))
        np.testing.assert_allclose(force[:3], push, rtol=0, atol=0.02)
        assert station.plant.HasModelInstanceNamed("hand")


def test_a_tool_moved_against_a_hand_that_stays_meets_its_spring():
    """With a reaction time far longer than the run the hand stays where
    it was: the arm moves the tool, and at rest the force is -K dx (to
    3%: SAP's ball constraint, the grip, yields a little too)."""
    offset = np.array([0.0, 0.03, 0.0, 0.0, 0.0, 0.0])
    for stiffness in (200.0, 600.0):
        hand = HandForce(times=[0.0, 1.0], forces=[[0, 0, 0], [0, 0, 0]],
                         impedance=HandImpedance(stiffness=stiffness,
                                                 reaction_time=1e4))
        [(force, p)], p0, _ = run_station(hand, offset, until=(1.5,))
        moved = p - p0
        assert np.linalg.norm(moved) > 0.01  # the arm did move the tool
        np.testing.assert_allclose(force[:3], -stiffness * moved, rtol=0,
                                   atol=0.03 * stiffness
                                   * np.linalg.norm(moved))


def test_without_an_impedance_the_station_has_no_hand_body():
    hand = HandForce(times=[0.0, 1.0, 2.0],
                     forces=[[0, 0, 0], [1, 0, 0], [1, 0, 0]])
    [(force, _)], _, station = run_station(hand, until=(1.5,))
    assert not station.plant.HasModelInstanceNamed("hand")
    np.testing.assert_allclose(force[:3], [1.0, 0.0, 0.0], atol=1e-12)
