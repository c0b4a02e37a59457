"""A robot the project did not model, for the tests of "bring your own
robot": a plain URDF of an omnidirectional base (three planar joints)
carrying an arm of n revolute joints, a flange, a wrist sensor and a
tool, every joint driven through a transmission, with no acceleration
limits (URDF has none), and its description
(drake_wbc.robot.description)."""

import textwrap


def urdf_text(n, continuous=()):
    """The URDF of an n-joint omni arm, the arm's joints of the indices
    `continuous` (0 the first) continuous (no position limits)."""
    axes = ["0 0 1", "0 1 0", "0 1 0", "0 0 1", "0 1 0", "0 0 1", "0 1 0"]
    links = ["<link name='world_x'/>", "<link name='world_y'/>",
             _link("chassis", 50.0)]
    joints = [
        _joint("base_x", "prismatic", "world", "world_x", axis="1 0 0"),
        _joint("base_y", "prismatic", "world_x", "world_y", axis="0 1 0"),
        _joint("base_yaw", "revolute", "world_y", "chassis", axis="0 0 1",
               limits=False)]
    parent = "chassis"
    for i in range(n):
        link = f"link{i + 1}"
        links.append(_link(link, 2.0))
        kind = "continuous" if i in continuous else "revolute"
        joints.append(_joint(f"j{i + 1}", kind, parent, link,
                             axis=axes[i % len(axes)],
                             xyz="0 0 0.3" if i else "0.2 0 0.4"))
        parent = link
    for name, child, xyz in (("flange", "flange", "0 0 0.1"),
                             ("sensor", "sensor", "0 0 0.02"),
                             ("tool", "tool", "0 0 0.05")):
        links.append(_link(child, 0.3))
        joints.append(_joint(name, "fixed", parent, child, xyz=xyz))
        parent = child
    actuated = ["base_x", "base_y", "base_yaw"] + [f"j{i + 1}"
                                                   for i in range(n)]
    transmissions = [
        f"<transmission name='{name}_drive'><type>"
        "transmission_interface/SimpleTransmission</type>"
        f"<joint name='{name}'><hardwareInterface>EffortJointInterface"
        f"</hardwareInterface></joint><actuator name='{name}_motor'>"
        "<mechanicalReduction>1</mechanicalReduction></actuator>"
        "</transmission>" for name in actuated]
    body = "\n".join(links + joints + transmissions)
    return f"<?xml version='1.0'?>\n<robot name='omni_arm'>\n{body}\n</robot>\n"


def _link(name, mass):
    return (f"<link name='{name}'><inertial><mass value='{mass}'/>"
            f"<inertia ixx='0.01' iyy='0.01' izz='0.01' ixy='0' ixz='0' "
            f"iyz='0'/></inertial></link>")


def _joint(name, kind, parent, child, axis=None, xyz="0 0 0", limits=True):
    text = (f"<joint name='{name}' type='{kind}'><parent link='{parent}'/>"
            f"<child link='{child}'/><origin xyz='{xyz}'/>")
    if axis:
        text += f"<axis xyz='{axis}'/>"
    if kind == "continuous":
        text += "<limit effort='100' velocity='2.0'/>"
    elif kind != "fixed" and limits:
        text += ("<limit lower='-2.5' upper='2.5' effort='100' "
                 "velocity='2.0'/>")
    return text + "</joint>"


HOMES = {6: [0.0, 0.8, 1.1, -0.4, -1.2, 0.3],
         7: [0.0, 0.5, 0.3, -0.2, 1.3, 0.2, 0.0]}
"""Homes of good manipulability (C_m 0.10 and 0.17, the TCP about 1 m
ahead and 1 m high), found by a random search over the joints."""


def description_text(n, extra=""):
    joints = ", ".join(f"omni_arm::j{i + 1}" for i in range(n))
    home = ", ".join(str(q) for q in HOMES.get(n, [0.3] * n))
    return textwrap.dedent(f"""\
        name: omni_arm
        model:
          file: omni_arm.urdf
        base:
          frame: omni_arm::chassis
          joints: [omni_arm::base_x, omni_arm::base_y, omni_arm::base_yaw]
          velocity_limits: [0.8, 0.8, 1.0]
          acceleration_limits: [0.5, 0.5, 0.5]
          footprint_half_sizes: [0.45, 0.35]
          height: 0.35
          command_timeout: 0.2
          velocity_lag: 0.2
        arm:
          joints: [{joints}]
          base_frame: omni_arm::chassis
          flange_frame: omni_arm::flange
          home: [{home}]
        EXTRA
        tool:
          tcp_frame: omni_arm::tool
          ft_sensor_frame: omni_arm::sensor
          ft_sensor_joint: omni_arm::sensor
          ft_sensor_range: [300.0, 300.0, 300.0, 30.0, 30.0, 30.0]
        """).replace("EXTRA\n", extra + "\n" if extra else "")


def write_omni_arm(folder, n, accelerations=True, extra="", continuous=()):
    """Writes the URDF and the description of an n-joint omni arm into
    `folder`; returns the description's path. With `accelerations` the
    description gives the arm's acceleration limits (9 rad/s^2, which the
    URDF cannot); `extra` adds lines under `arm:`; the arm's joints of
    the indices `continuous` are continuous."""
    lines = [f"  acceleration_limits: [{', '.join(['9.0'] * n)}]"] \
        if accelerations else []
    if extra:
        lines.append(extra)
    (folder / "omni_arm.urdf").write_text(urdf_text(n, continuous))
    path = folder / "omni_arm.yaml"
    path.write_text(description_text(n, extra="\n".join(lines)))
    return path


def write_scenario(folder, robot, duration, extra=""):
    """Writes a scenario on the 7-joint omni arm of the description
    `robot` (in `folder`): the arm at its home, the tuning the demo
    proposes (the base's limits, footprint and stop distance its own, by
    default), the world twist [0.05, 0, 0.02] m/s; `extra` adds
    top-level lines. Returns its path."""
    path = folder / "scenario.yaml"
    path.write_text(textwrap.dedent(f"""\
        description: the omni arm follows a world twist
        duration: {duration}
        robot: {robot.name}
        station:
          initial_arm_positions: {HOMES[7]}
        controller:
          capability:
            joint_limit_gain: 6.0e4
          capability_band: {{lower: 0.18, upper: 0.21}}
        task:
          reference_velocity:
            times: [0.0]
            values: [[0.05, 0.0, 0.02, 0.0, 0.0, 0.0]]
        """) + extra)
    return path


def add_collision_spheres(folder, radii):
    """Gives the omni arm's links in `folder` collision spheres at their
    frames' origins: `radii` maps a link's name (e.g. link3) to its
    sphere's radius (m)."""
    urdf = folder / "omni_arm.urdf"
    text = urdf.read_text()
    for link, radius in radii.items():
        head = f"<link name='{link}'>"
        assert head in text, link
        text = text.replace(head, head + (
            f"<collision><geometry><sphere radius='{radius}'/></geometry>"
            "</collision>"))
    urdf.write_text(text)


SELF_FILTER = """\
- add_collision_filter_group:
    name: robot
    members: [omni_arm::link1, omni_arm::link3]
    ignored_collision_filter_groups: [robot]
"""
"""The README's directive that filters the omni arm's link1 and link3."""


def use_directives(folder, path, extra=""):
    """Makes the omni arm's description `path` (in `folder`) load its URDF
    through model directives, robot.dmd.yaml, to which `extra` adds
    directives."""
    (folder / "robot.dmd.yaml").write_text(
        "directives:\n- add_model: {name: omni_arm, file: "
        "package://mine/omni_arm.urdf}\n" + extra)
    path.write_text(path.read_text().replace(
        "file: omni_arm.urdf",
        "directives: robot.dmd.yaml\n  packages: {mine: .}"))
