"""A report of the robot model: its joints and limits, its capability of
movement at a pose, and a Meshcat page of it as a self-contained HTML file.

This is what `drake-wbc demo` prints and writes: the first look a user gets
at the robot the controller drives.
"""

import numpy as np
from pydrake.geometry import MeshcatVisualizer, Rgba
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import ModelInstanceIndex
from pydrake.systems.framework import DiagramBuilder
from pydrake.visualization import AddFrameTriadIllustration

from drake_wbc.experiments.replay import quiet_meshcat, write_static_html
from drake_wbc.math import capability
from drake_wbc.math.validation import as_vector
from drake_wbc.robot.model import (
    ArmKinematics,
    add_robot,
    joint_position_indices,
    make_robot_plant,
    mount_rocking_modes,
    self_contacts,
)
from drake_wbc.robot.tuning import (
    BAND_OVER_HOME,
    EXTENT_OVER_HOME,
    check_tuning,
    home_extent,
    mid_range_penalty,
    proposed_local_workspace,
    singular,
    survey_capability,
)

LIDAR_FIELD_OF_VIEW = np.radians(270.0)
"""The SICK TiM571's field of view (the facts sheet)."""


def describe_robot(q_a=None, k_j=None, description=None):
    """Returns a text report of the robot model at arm configuration `q_a`
    (its home if None).

    Lists every moving joint with its limits (the arm's own, ArmLimits:
    the description's where it tightens the model's) and its actuator's
    effort limit (a mount's joints are spring-dampers; a base or arm
    joint without an actuator is said to have none, which the simulated
    station refuses), the masses, the mount's rocking modes (with a
    two-joint mount), the base's described limits, footprint, timeout and
    lag (what the controller's safety takes), and the capability of movement (m,
    P_jnt, C_m and grad_x C_m) at `q_a`.

    Args:
        q_a: (n,) the arm's joints, rad.
        k_j: the joint-limit gain (the default if None).
        description: the RobotDescription (the shipped robot if None).
    """
    k_j = capability.DEFAULT_JOINT_LIMIT_GAIN if k_j is None else k_j
    plant, model = make_robot_plant(description)
    q_a = as_vector("q_a", model.home if q_a is None else q_a,
                    model.num_arm_joints)
    context = plant.CreateDefaultContext()
    actuated = {
        plant.get_joint_actuator(i).joint().index(): plant.get_joint_actuator(
            i
        ).effort_limit()
        for i in plant.GetJointActuatorIndices()
    }
    lines = ["Joints (position limits, velocity limit, effort limit):"]
    groups = (
        ("base", model.base_joints),
        ("mount", model.passive_joints),
        ("arm", model.arm_joints),
    )
    # The names' column as wide as the longest (a vendor's joint names,
    # e.g. `shoulder_lift_joint`, are longer than the shipped robot's).
    width = max([12] + [len(j.name()) for _, joints in groups
                        for j in joints])
    # The arm's limits are its own: what its controller and the LCM
    # guard hold it to.
    own = {joint.index(): i for i, joint in enumerate(model.arm_joints)}
    for group, joints in groups:
        for joint in joints:
            name = joint.name()
            unit = "m" if joint.type_name() == "prismatic" else "rad"
            low = joint.position_lower_limits()[0]
            high = joint.position_upper_limits()[0]
            speed = joint.velocity_upper_limits()[0]
            if joint.index() in own:
                i = own[joint.index()]
                low, high = model.limits.lower[i], model.limits.upper[i]
                speed = model.limits.velocity[i]
            limits = (
                "unlimited"
                if np.isinf(low) and np.isinf(high)
                else f"[{low:+.2f}, {high:+.2f}] {unit}"
            )
            if joint.index() in actuated:
                effort = (f"{actuated[joint.index()]:6.0f} "
                          f"{'N' if unit == 'm' else 'N m'}")
            elif group == "mount":
                # A passive joint has a spring (add_robot checks it).
                effort = "unactuated (spring-damper)"
            else:
                effort = "no actuator (the simulated station refuses it)"
            lines.append(
                f"  {group:5s} {name:{width}s} {joint.type_name():9s} "
                f"{limits:24s} {f'{speed:5.2f} {unit}/s':11s}  {effort}"
            )

    def mass(instance):
        return sum(
            plant.get_body(b).get_mass(context)
            for b in plant.GetBodyIndices(instance)
        )

    if len({model.base, model.arm, model.tool}) == 3:
        lines.append(
            f"Masses: base {mass(model.base):.1f} kg, arm "
            f"{mass(model.arm):.2f} kg, sensor and tool "
            f"{mass(model.tool):.2f} kg")
    else:
        lines.append(f"Mass of the robot: {mass(model.arm):.1f} kg")
    if len(model.passive_joints) == 2:
        modes = mount_rocking_modes(plant, model, q_a)
        lines.append(
            "Mount rocking modes: "
            + ", ".join(
                f"{mode.frequency_hz:.2f} Hz (damping ratio "
                f"{mode.damping_ratio:.3f})"
                for mode in modes
            )
        )
    base = model.description.base
    footprint = 2.0 * np.asarray(base.footprint_half_sizes)
    lines += [
        "Base, as described (the controller's limits may only tighten "
        "these):",
        f"  velocity limits {list(base.velocity_limits)} (m/s, m/s, "
        f"rad/s), acceleration limits {list(base.acceleration_limits)}",
        f"  footprint {footprint[0]:.2f} x {footprint[1]:.2f} m, stops "
        f"itself {base.command_timeout:g} s after the last command, "
        f"velocity loop lag {base.velocity_lag:g} s"]
    kinematics = ArmKinematics(plant, model)
    values = kinematics.evaluate(q_a)
    lower, upper = kinematics.lower, kinematics.upper
    m = capability.manipulability(values.J_a)
    penalty = capability.joint_limit_penalty(q_a, lower, upper, k_j)
    gradient = capability.capability_gradient(values.J_a, q_a, lower, upper,
                                              k_j)
    p = values.p_ee_in_base
    lines += [
        f"Arm configuration q_a = {np.array2string(q_a, precision=3)} rad",
        f"End effector (tool centre point) in the base frame: "
        f"[{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] m",
        f"Capability of movement (k_j = {k_j:g}): manipulability m = "
        f"{m:.4f}, joint-limit penalty P_jnt = {penalty:.3f}, "
        f"C_m = {m * penalty:.4f}",
        "grad_x C_m = "
        + np.array2string(gradient, precision=4, suppress_small=True)
        + "  ([v; w] in the arm's base frame)",
    ]
    return "\n".join(lines)


def describe_tuning(arm, band, k_j, local_workspace, count=2000):
    """Returns a text report of what the capability band, k_j and the
    local workspace (LocalWorkspace) mean on `arm` (ArmKinematics): C_m
    at home and over `count` random configurations, with the given k_j
    and with the one proposed for the arm, the band and the local
    workspace proposed there (drake_wbc.robot.tuning), and what is wrong
    with the given tuning."""
    given = survey_capability(arm, k_j, count)
    proposed = survey_capability(arm, None, count)
    band_there = None if singular(arm) else proposed.proposed_band()
    workspace_there = proposed_local_workspace(arm)
    percentiles = np.percentile(proposed.samples, [50, 90, 99])
    lines = [
        f"Tuning for this arm ({arm.num_joints} joints, {count} random "
        "configurations within its limits):",
        f"  with k_j = {k_j:g} and the band ({band.lower:g}, "
        f"{band.upper:g}): C_m at home {given.home:.4g}, "
        f"{100 * given.fraction_below(band.upper):.1f}% of the "
        "configurations below the band's top",
        f"  proposed k_j = {proposed.k_j:.4g} (P_jnt "
        f"{mid_range_penalty(proposed.k_j, arm.num_joints):.3f} with every "
        f"joint mid-range): C_m at home {proposed.home:.4g}, median "
        f"{percentiles[0]:.3g}, 90th percentile {percentiles[1]:.3g}, 99th "
        f"{percentiles[2]:.3g}",
        "  proposed capability_band: none, the home is at or near a "
        "singularity (below)"
        if band_there is None else
        f"  proposed capability_band: ({band_there.lower:.4g}, "
        f"{band_there.upper:.4g}), at {BAND_OVER_HOME[0]:.2f} and "
        f"{BAND_OVER_HOME[1]:.2f} of the home's C_m as the paper's band on "
        f"the shipped arm; "
        f"{100 * proposed.fraction_below(band_there.upper):.1f}% of the "
        "configurations lie below it",
        f"  proposed local_workspace (intuitive pHRI): extents "
        f"({workspace_there.extent_lower:.3g}, "
        f"{workspace_there.extent_upper:.3g}) m, at "
        f"{EXTENT_OVER_HOME[0]:.3f} and {EXTENT_OVER_HOME[1]:.3f} of the "
        f"tool's extent at home, {home_extent(arm):.4g} m, as the paper's "
        f"on the shipped arm (given: ({local_workspace.extent_lower:.3g}, "
        f"{local_workspace.extent_upper:.3g}) m)",
    ]
    problems = check_tuning(arm, band, k_j, local_workspace)
    lines += [f"  to change: {problem}" for problem in problems] or [
        "  the given tuning suits this arm"]
    return "\n".join(lines)


def _lidar_fan(radius, segments=48):
    """Vertices and faces of a flat 270 degree fan about the x axis."""
    angles = np.linspace(-LIDAR_FIELD_OF_VIEW / 2, LIDAR_FIELD_OF_VIEW / 2,
                         segments + 1)
    rim = np.stack(
        [radius * np.cos(angles), radius * np.sin(angles),
         np.zeros_like(angles)]
    )
    vertices = np.hstack([np.zeros((3, 1)), rim])
    faces = np.array(
        [[0, i, i + 1] for i in range(1, segments + 1)], dtype=np.int32
    ).T
    return vertices, faces


def write_model_page(path, q_a=None, lidar_range=1.0, description=None):
    """Writes a self-contained HTML page that shows the robot in Meshcat.

    The page draws the robot at arm configuration `q_a` (base and mount at
    rest), the frames the controller uses (base, arm base, tool centre
    point, force/torque measurement, LIDARs) as RGB triads, and the LIDARs'
    270 degree fields of view as translucent fans of radius `lidar_range`.
    It needs no server or network to open.

    Args:
        path: the file to write (its folder is created).
        q_a: the arm configuration (n,) in rad (the home if None).
        lidar_range: the radius of the drawn fields of view, m.
        description: the RobotDescription (the shipped robot if None).

    Returns:
        (pathlib.Path, list): the written file, and the robot's own
        bodies that overlap at `q_a` (drake_wbc.robot.model.self_contacts:
        the simulated station refuses them).
    """
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.0)
    first = plant.num_model_instances()
    model = add_robot(plant, description)
    instances = [ModelInstanceIndex(i)
                 for i in range(first, plant.num_model_instances())]
    q_a = as_vector("q_a", model.home if q_a is None else q_a,
                    model.num_arm_joints)
    plant.Finalize()
    frames = (
        model.base_frame,
        model.arm_base_frame,
        model.tcp_frame,
        model.ft_measurement_frame,
        *model.lidar_frames,
    )
    drawn = set()
    for frame in frames:
        if frame.index() in drawn:  # e.g. T_a on T_b's body frame
            continue
        drawn.add(frame.index())
        AddFrameTriadIllustration(
            scene_graph=scene_graph, frame=frame, length=0.12, radius=0.004
        )
    meshcat = quiet_meshcat()
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    q = plant.GetPositions(plant_context)
    q[joint_position_indices(model.arm_joints)] = q_a
    plant.SetPositions(plant_context, q)
    vertices, faces = _lidar_fan(lidar_range)
    for frame in model.lidar_frames:
        name = f"/lidar_fields/{frame.name()}"
        meshcat.SetTriangleMesh(
            name, vertices, faces, Rgba(0.95, 0.8, 0.1, 0.25)
        )
        meshcat.SetTransform(name, frame.CalcPoseInWorld(plant_context))
    meshcat.SetTransform("/lidar_fields", RigidTransform())
    diagram.ForcedPublish(context)
    return (write_static_html(meshcat, path),
            self_contacts(plant, plant_context, instances))


def describe_self_contacts(contacts):
    """What `demo` says of the robot's own bodies that overlap
    (`write_model_page`'s list), or "" where none do."""
    if not contacts:
        return ""
    pairs = "; ".join(f"{a} and {b} by {1e3 * depth:.1f} mm"
                      for a, b, depth in contacts)
    return (f"The robot's own bodies overlap at this configuration: {pairs}."
            " The simulated station refuses a robot whose bodies overlap "
            "at its home or start: filter their contacts in the model "
            "directives (README, \"Use your own robot\"), or give "
            "another configuration.")
