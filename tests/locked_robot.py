"""A test fixture: the simulated robot held still, to read its sensing weld.

Every joint is locked with the arm at a given configuration (base at the
origin, mount at rest, so T_b is the world frame, and T_a parallel to it
for the shipped mount), optionally with a wrench applied at the tool
centre point, and the discrete plant is advanced until the weld forces
settle.
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import (
    AddMultibodyPlantSceneGraph,
    ExternallyAppliedSpatialForce,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource

from drake_wbc.robot.model import add_robot, joint_position_indices


def settle_locked_robot(q_a, push_at_tcp_W=None, duration=0.05,
                        mount=None):
    """Returns (plant, model, plant_context) after `duration` s at rest.

    Args:
        q_a: (6,) arm configuration.
        push_at_tcp_W: a SpatialForce applied to the tool at its tool
            centre point, expressed in the world frame, or None.
        mount: the robot's ArmMount (the shipped one if None).
    """
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    model = add_robot(plant, mount=mount)
    plant.Finalize()
    if push_at_tcp_W is not None:
        applied = ExternallyAppliedSpatialForce()
        applied.body_index = plant.GetBodyByName("wiping_tool",
                                                 model.tool).index()
        applied.p_BoBq_B = model.tcp_frame.GetFixedPoseInBodyFrame(
        ).translation()
        applied.F_Bq_W = push_at_tcp_W
        source = builder.AddSystem(ConstantValueSource(
            AbstractValue.Make([applied])))
        builder.Connect(source.get_output_port(),
                        plant.get_applied_spatial_force_input_port())
    simulator = Simulator(builder.Build())
    context = plant.GetMyMutableContextFromRoot(
        simulator.get_mutable_context())
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = q_a
    plant.SetPositions(context, q)
    for i in plant.GetJointIndices():
        if plant.get_joint(i).num_velocities() == 1:
            plant.get_joint(i).Lock(context)
    simulator.AdvanceTo(duration)
    return plant, model, context


def sensing_weld_reaction(plant, model, context):
    """The reaction of the weld `ft300_sensing`: the spatial force on the
    tool at the measurement frame, expressed in it."""
    weld = plant.GetJointByName("ft300_sensing", model.tool)
    return plant.get_reaction_forces_output_port().Eval(context)[
        int(weld.index())]


def sensor_reading(plant, model, context):
    """What the FT-300 reads: the wrench [f; tau] the tool exerts on it,
    minus the weld's reaction."""
    reaction = sensing_weld_reaction(plant, model, context)
    return -np.concatenate([reaction.translational(), reaction.rotational()])
