"""The station's base driver and plant, linearised: the base's real
velocity loop (the driver, the plant's in-plant velocity servo, the
flexible mount, the arm held by its servo) around the station's static
equilibrium, and what the plant's state gives of the base's and the end
effector's velocities. drake_wbc.analysis.chains puts it after the split
of the end-effector command."""


import numpy as np
from pydrake.multibody.plant import (
    DiscreteContactApproximation,
    MultibodyPlant,
)
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LinearSystem

from drake_wbc.analysis.period_map import linearize_period_map
from drake_wbc.station.drivers import BaseVelocityDriver
from drake_wbc.station.simulation import SimulatedStation, add_desired_states
from drake_wbc.station.state_sensors import BaseOdometry

PLANT_OUTPUTS = (("base_velocity", 3), ("end_effector_velocity", 6))
"""What `plant_outputs` reads off the plant, in T_b: the base's actual
velocity [vx, vy, wz] and the end effector's twist [v; w] (with the
split, the arm's share added), in this order after the shares."""



def add_robot_plant(builder, station):
    """Adds to `builder` (named "plant") a copy of the SimulatedStation
    `station`'s plant, not yet finalised: the robot alone (no scene graph,
    so no contact; the outputs unsampled, so its only state is [q; v]) at
    the station's step, as the station has it (its suspension, mount,
    servo gains and drive inertias: SimulatedStation.add_robot_to).
    Returns (plant, model)."""
    if not isinstance(station, SimulatedStation):
        raise ValueError(f"station = {station!r} is not allowed: must be a "
                         "SimulatedStation")
    plant = builder.AddNamedSystem("plant", MultibodyPlant(
        station.options.time_step))
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)
    plant.SetUseSampledOutputPorts(False)
    model = station.add_robot_to(plant)
    if model.locked_joints:
        # The period map's AutoDiffXd step of this plant with a locked
        # joint and its servos' PD gains fails in Drake's SAP solver (a
        # constraint's Jacobian of the wrong size; in double it steps),
        # and unlocked the tool's joints would swing.
        raise ValueError(
            f"station is not allowed: its robot's tool.locked_joints = "
            f"{list(model.description.tool.locked_joints)} cannot be held "
            "in the plant chain's linearisation (AutoDiffXd); analyse a "
            "copy of the robot's model with those joints welded")
    return plant, model


def add_station_plant(builder, station):
    """Adds to `builder` the SimulatedStation `station`'s base driver and a
    copy of its plant: the robot alone (no scene graph, so no contact; the
    outputs unsampled, so its only state is [q; v]) with the station's
    servo gains; the base's velocity servo fed the driver's desired_state,
    the driver the pose of BaseOdometry, the arm's servo held at
    options.initial_arm_positions. Returns (driver, plant, model)."""
    plant, model = add_robot_plant(builder, station)
    options = station.options
    h = options.time_step
    add = builder.AddNamedSystem
    plant.Finalize()
    driver = add("base_driver", BaseVelocityDriver(options.base, h))
    odometry = add("odometry", BaseOdometry(plant, model))
    hold = add("arm_hold", ConstantVectorSource(np.concatenate(
        [options.initial_arm_positions,
         np.zeros(len(options.initial_arm_positions))])))
    builder.Connect(plant.get_state_output_port(),
                    odometry.GetInputPort("plant_state"))
    builder.Connect(odometry.GetOutputPort("pose"),
                    driver.GetInputPort("base_pose"))
    add_desired_states(builder, plant, model,
                       driver.GetOutputPort("desired_state"),
                       hold.get_output_port())
    return driver, plant, model


def station_at_rest(station):
    """The SimulatedStation `station` at its static equilibrium
    (`SimulatedStation.set_initial_state`): (its root context, its
    plant's own). The station may be part of another diagram."""
    root = station.diagram.CreateDefaultContext()
    station.set_initial_state(root)
    return root, station.diagram.GetSubsystemContext(station.plant, root)


def station_equilibrium(station, plant, model, context):
    """Puts `plant` (of `add_station_plant`) in `context` (its root's) at
    the station's static equilibrium, `SimulatedStation.set_initial_state`,
    at rest. Returns the plant's own context."""
    _, settled = station_at_rest(station)
    mine = plant.GetMyMutableContextFromRoot(context)
    for name in ("base", "arm", "tool"):
        plant.SetPositions(mine, getattr(model, name),
                           station.plant.GetPositions(
                               settled, getattr(station.model, name)))
    plant.SetVelocities(mine, np.zeros(plant.num_velocities()))
    return mine


def plant_outputs(plant, model, context):
    """The (9, nq + nv) map from a change of the plant's state [q; v] at
    rest (in `context`) to PLANT_OUTPUTS in T_b: the base's velocity
    [vx, vy, wz] and the tool centre point's twist [v; w] (what
    GroundTruth reports, turned into T_b). Both twists are J(q) v, so
    at v = 0 this is their exact first-order change."""
    world = plant.world_frame()
    R = model.base_frame.CalcPoseInWorld(context).rotation().matrix().T

    def twist(frame):  # [v; w] in T_b per v, (6, nv)
        J = plant.CalcJacobianSpatialVelocity(
            context, JacobianWrtVariable.kV, frame, np.zeros(3), world, world)
        return np.vstack([R @ J[3:], R @ J[:3]])

    base = twist(model.base_frame)
    nq = plant.num_positions()
    S = np.zeros((9, nq + plant.num_velocities()))
    S[:, nq:] = np.vstack([base[[0, 1, 5]], twist(model.tcp_frame)])
    return S


def linearize_base_plant(station, period=None):
    """The base's real velocity loop with the plant: the LinearSystem from
    the velocity command (3, T_b) of the SimulatedStation `station`'s
    BaseVelocityDriver, through the plant's base servo and the flexible
    mount, to PLANT_OUTPUTS (9), around the station's static equilibrium;
    the AutoDiff period map over `period` (the plant's step if None, a
    whole multiple of it)."""
    builder = DiagramBuilder()
    driver, plant, model = add_station_plant(builder, station)
    builder.ExportInput(driver.GetInputPort("velocity_command"),
                        "velocity_command")
    builder.ExportOutput(plant.get_state_output_port(), "plant_state")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    mine = station_equilibrium(station, plant, model, context)
    command = diagram.GetInputPort("velocity_command")
    command.FixValue(context, np.zeros(3))
    linear = linearize_period_map(
        diagram, context, station.options.time_step if period is None
        else period, command, diagram.GetOutputPort("plant_state"))
    S = plant_outputs(plant, model, mine)
    return LinearSystem(linear.A(), linear.B(), S @ linear.C(),
                        S @ linear.D(), linear.time_period())
