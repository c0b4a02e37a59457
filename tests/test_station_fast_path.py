"""The station's float shortcuts against plain formulations of the same
math: the F/T measurement, the schedules' interpolation (numpy's, bit for
bit), the end effector's motion from the plant's kinematics and the
merger's caching."""

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RollPitchYaw
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder, LeafSystem

from drake_wbc.robot.description import shipped_robot
from drake_wbc.robot.model import add_robot
from drake_wbc.station.force_torque import (
    ForceTorqueSensorParameters,
    measure,
)
from drake_wbc.station.lidar import ObstaclePointMerger
from drake_wbc.station.scene import (
    HandForce,
    HandSchedule,
    WalkingPerson,
    Walks,
)
from drake_wbc.station.state_sensors import GroundTruth


def _per_axis(force, torque):
    return np.array([force] * 3 + [torque] * 3, dtype=float)


def reference_measure(wrench, params, tick):
    """The measurement as first written: noise, np.minimum/np.maximum,
    np.round, np.where."""
    std = _per_axis(params.force_noise_std, params.torque_noise_std)
    own = shipped_robot().tool.ft_sensor_range  # the robot's own range
    limit = _per_axis(own[0] if params.force_range is None
                      else params.force_range,
                      own[3] if params.torque_range is None
                      else params.torque_range)
    resolution = _per_axis(params.force_resolution, params.torque_resolution)
    reading = np.asarray(wrench, dtype=float)
    if np.any(std > 0.0):
        rng = np.random.default_rng([params.seed, tick])
        reading = reading + std * rng.standard_normal(6)
    reading = np.minimum(np.maximum(reading, -limit), limit)
    step = np.where(resolution > 0.0, resolution, 1.0)
    return np.where(resolution > 0.0, np.round(reading / step) * step,
                    reading)


@pytest.mark.parametrize("fields", [
    {}, {"seed": 7}, {"force_noise_std": 0.0, "torque_noise_std": 0.0},
    {"force_resolution": 0.0}, {"force_resolution": 0.0,
                                "torque_resolution": 0.0},
    {"force_range": 1.0, "torque_range": 0.05, "force_resolution": 0.5}])
def test_measurement_is_the_plain_formula_bit_for_bit(fields):
    params = ForceTorqueSensorParameters(**fields)
    rng = np.random.default_rng(11)
    for tick in range(500):
        wrench = rng.normal(size=6) * rng.choice([1e-3, 1.0, 50.0, 1e3])
        if tick % 50 == 0:  # halfway between two quantisation steps
            wrench = np.array([0.005, -0.015, 0.025, 5e-4, -1.5e-3, 0.0])
        kept = wrench.copy()
        reading = measure(wrench, params, tick)
        np.testing.assert_array_equal(
            reading, reference_measure(wrench, params, tick))
        np.testing.assert_array_equal(wrench, kept)  # input untouched


def test_schedules_are_numpys_interpolation():
    people = [WalkingPerson(name="a", times=[0.5, 1.5, 4.0],
                            waypoints=[[0, 2], [1, 1], [2, 2]]),
              WalkingPerson(name="b", times=[1.0, 3.0],
                            waypoints=[[0, 0], [3, -1]], repeat=4.0),
              WalkingPerson(name="c", times=[2.0], waypoints=[[5, 5]])]
    hand = HandForce(times=[1.0, 1.5, 3.0], forces=[[0, 0, 0], [0, 15, 2],
                                                    [1, 0, 0]],
                     torques=[[0, 0, 0], [0, 0, 0.5], [0, 0, 0]])
    walks, schedule = Walks(people), HandSchedule(hand)
    columns = np.hstack([np.asarray(hand.forces), np.asarray(hand.torques)])
    for t in np.concatenate([np.linspace(-1.0, 12.0, 400),
                             [0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 9.0]]):
        want = []
        for p in people:
            s = (p.times[0] + (t - p.times[0]) % p.repeat
                 if p.repeat > 0.0 and t > p.times[0] else t)
            path = np.asarray(p.waypoints, dtype=float)
            want.append([np.interp(s, p.times, path[:, 0]),
                         np.interp(s, p.times, path[:, 1])])
        np.testing.assert_array_equal(walks(t), want)
        np.testing.assert_array_equal(
            schedule(t), [np.interp(t, hand.times, columns[:, k], left=0.0,
                                    right=0.0) for k in range(6)])


@pytest.fixture(scope="module")
def robot():
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0),
                                 builder)
    model = add_robot(plant)
    plant.Finalize()
    truth = builder.AddSystem(GroundTruth(plant, model))
    builder.Connect(plant.get_state_output_port(),
                    truth.GetInputPort("plant_state"))
    return builder.Build(), plant, model, truth


def test_end_effector_motion_matches_the_plants_kinematics(robot):
    diagram, plant, model, truth = robot
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    truth_context = truth.GetMyContextFromRoot(context)
    rng = np.random.default_rng(3)
    for _ in range(5):
        plant.SetPositions(plant_context,
                           rng.uniform(-0.5, 0.5, plant.num_positions()))
        plant.SetVelocities(plant_context,
                            rng.uniform(-1.0, 1.0, plant.num_velocities()))
        tcp = model.tcp_frame
        X = tcp.CalcPoseInWorld(plant_context)
        V = tcp.CalcSpatialVelocityInWorld(plant_context)
        pose = truth.GetOutputPort("end_effector_pose").Eval(truth_context)
        velocity = truth.GetOutputPort("end_effector_velocity").Eval(
            truth_context)
        np.testing.assert_allclose(pose[:3], X.translation(), atol=1e-12)
        np.testing.assert_allclose(
            pose[3:], RollPitchYaw(X.rotation()).vector(), atol=1e-12)
        np.testing.assert_allclose(velocity, V.get_coeffs()[[3, 4, 5, 0, 1,
                                                             2]],
                                   atol=1e-12)


class PointsSource(LeafSystem):
    """Outputs the points in its discrete state (M, 2), as a LIDAR's
    points follow its last reading: recomputed only when the state
    changes."""

    def __init__(self, points):
        super().__init__()
        self.shape = np.shape(points)
        state = self.DeclareDiscreteState(np.ravel(points))
        self.DeclareAbstractOutputPort(
            "points", lambda: AbstractValue.Make(np.zeros((0, 2))),
            lambda context, output: output.set_value(
                context.get_discrete_state(state).CopyToVector().reshape(
                    self.shape)),
            prerequisites_of_calc={self.discrete_state_ticket(state)})


def test_merger_merges_again_only_when_an_input_changes():
    a = np.array([[1.0, 2.0], [3.0, 4.0]])
    b = np.array([[5.0, 6.0]])
    builder = DiagramBuilder()
    sources = [builder.AddSystem(PointsSource(a)),
               builder.AddSystem(PointsSource(b))]
    merger = builder.AddSystem(ObstaclePointMerger(2))
    for i, source in enumerate(sources):
        builder.Connect(source.get_output_port(),
                        merger.GetInputPort(f"points_{i}"))
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    port = merger.GetOutputPort("points")
    merger_context = merger.GetMyContextFromRoot(context)

    first = port.Eval(merger_context)
    np.testing.assert_array_equal(first, np.vstack([a, b]))
    assert not first.flags.writeable
    context.SetTime(1.0)  # time alone: the same array, not merged again
    assert port.Eval(merger_context) is first
    c = np.array([[7.0, 8.0]])  # a new reading of the second source
    sources[1].GetMyMutableContextFromRoot(context).SetDiscreteState(
        np.ravel(c))
    second = port.Eval(merger_context)
    assert second is not first
    np.testing.assert_array_equal(second, np.vstack([a, c]))
