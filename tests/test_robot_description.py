"""The robot as data: the shipped robot's description against its model,
a robot the project did not model (a URDF written here, with 6 and 7 arm
joints), and every way a description can be wrong, each an error naming
the field."""

import re

import numpy as np
import pytest
import yaml
from omni_arm import urdf_text, write_omni_arm
from pydrake.multibody.plant import MultibodyPlant

from drake_wbc.robot.description import (
    MIN_ARM_JOINTS,
    BaseDescription,
    RobotDescription,
    ToolDescription,
    load_robot_description,
    models_dir,
    shipped_robot,
)
from drake_wbc.robot.model import (
    ArmKinematics,
    add_robot,
    joint_position_indices,
    make_robot_plant,
)

SHIPPED = models_dir() / "mcr.robot.yaml"


def test_the_shipped_description_is_its_model():
    plant, model = make_robot_plant()
    description = shipped_robot()
    assert [f"{plant.GetModelInstanceName(j.model_instance())}::{j.name()}"
            for j in model.arm_joints] == list(description.arm.joints)
    assert model.num_arm_joints == 6
    np.testing.assert_array_equal(model.home, description.arm.home)
    # No override: the limits are the model file's.
    for joint, lower, speed in zip(model.arm_joints, model.limits.lower,
                                   model.limits.velocity, strict=True):
        assert lower == joint.position_lower_limits()[0]
        assert speed == joint.velocity_upper_limits()[0]
    assert [f.name() for f in model.lidar_frames] == [
        n.split("::")[1] for n in description.lidar_frames]


def _shipped_text(**changes):
    """The shipped description's YAML with `changes` applied: a dotted
    path -> new value (None deletes the key)."""
    document = yaml.safe_load(SHIPPED.read_text())
    for path, value in changes.items():
        *parents, key = path.split(".")
        node = document
        for parent in parents:
            node = node[parent]
        if value is None:
            del node[key]
        else:
            node[key] = value
    return yaml.safe_dump(document)


def _add(text):
    description = load_robot_description(text=text, root=models_dir())
    plant = MultibodyPlant(time_step=0.0)
    return add_robot(plant, description)


@pytest.mark.parametrize("changes, message", [
    ({"arm.joints": ["elfin5::joint1", "elfin5::joint2"]},
     r"arm.joints = .* must name at least 6"),
    ({"arm.home": [0.0] * 5}, r"arm.home"),
    ({"base.joints": ["mcr_base::base_x", "mcr_base::base_y"]},
     r"base.joints = .* exactly 3"),
    ({"base.velocity_limits": [1.0, -1.0, 1.0]},
     r"base.velocity_limits\[1\] = -1.0"),
    ({"tool": None}, r"tool is missing"),
    ({"base.velocity_lag": None}, r"base.velocity_lag is missing: a robot "
     r"description must give it"),
    ({"base.command_timeout": None}, r"base.command_timeout is missing"),
    ({"base.velocity_limits": None}, r"base.velocity_limits is missing"),
    ({"base.frame": None}, r"base.frame is missing"),
    ({"arm.home": None}, r"arm.home is missing"),
    ({"tool.ft_sensor_joint": None}, r"tool.ft_sensor_joint is missing"),
    ({"tool.ft_sensor_range": None}, r"tool.ft_sensor_range is missing"),
    ({"tool.ft_sensor_range": [300.0] * 3 + [30.0, 0.0, 30.0]},
     r"tool.ft_sensor_range\[4\] = 0.0 is not allowed"),
    ({"tool.ft_sensor_range": [300.0] * 3}, r"tool.ft_sensor_range"),
    ({"arm.position_lower": [0.0] * 6, "arm.position_upper": [0.0] * 6},
     r"arm.position_lower\[0\] = 0.0 is not allowed: must be below"),
    ({"arm.flange": "elfin5::flange"}, r"arm.flange"),
    ({"tuning.joint_limit_gain": -1.0},
     r"tuning.joint_limit_gain = -1.0 is not allowed"),
    ({"tuning.capability_band": {"lower": 0.04, "upper": 0.035}},
     r"tuning.capability_band.lower = 0.04 and "
     r"tuning.capability_band.upper = 0.035 are not allowed"),
])
def test_a_description_that_does_not_load_names_the_field(changes, message):
    with pytest.raises(ValueError, match=message):
        load_robot_description(text=_shipped_text(**changes))


@pytest.mark.parametrize("changes, message", [
    ({"arm.joints": [f"elfin5::joint{i}" for i in (1, 2, 3, 4, 5, 7)]},
     r"arm.joints\[5\] = 'elfin5::joint7' is not allowed: the model has no "
     r"joint 'joint7'"),
    ({"arm.joints": [f"elfin5::joint{i}" for i in (1, 2, 4, 3, 5, 6)]},
     r"arm.joints\[3\] = 'elfin5::joint3' is not allowed: it is not "
     r"outboard of arm.joints\[2\]"),
    ({"arm.base_frame": "nowhere::base_link"},
     r"arm.base_frame = 'nowhere::base_link' is not allowed: must be "
     r"scoped by one of the model's instances"),
    ({"arm.base_frame": "elfin5::link3"},
     r"arm.base_frame = 'elfin5::link3' is not allowed: must not be "
     r"outboard of arm.joints\[0\] = 'elfin5::joint1'"),
    ({"base.joints": ["mcr_base::base_x", "mcr_base::base_yaw",
                      "mcr_base::base_y"]},
     r"base.joints\[1\] = 'mcr_base::base_yaw' is not allowed: it is a "
     r"revolute joint, must be prismatic"),
    ({"tool.tcp_frame": "mcr_base::base_link"},
     r"tool.tcp_frame = 'mcr_base::base_link' is not allowed: must be "
     r"outboard of the sensor"),
    ({"tool.ft_sensor_frame": "elfin5::link3"},
     r"tool.ft_sensor_frame = 'elfin5::link3' is not allowed: must be "
     r"outboard of the flange"),
    ({"arm.velocity_limits": [2.0] + [1.0] * 5},
     r"arm.velocity_limits\[0\] = 2.0 is not allowed: must be within the "
     r"model's own 1.57"),
    ({"arm.position_lower": [-3.5] + [-1.0] * 5,
      "arm.position_upper": [1.0] * 6},
     r"arm.position_lower\[0\] = -3.5 is not allowed: must be within the "
     r"model's own -3.14"),
    ({"arm.position_lower": [-1.1] * 6, "arm.position_upper": [1.1] * 6},
     r"arm.home\[4\] = 1.15 is not allowed: must be inside"),
    ({"lidar_frames": ["mcr_base::lidar_front_left", "elfin5::link3"]},
     r"lidar_frames\[1\] = 'elfin5::link3' is not allowed: must be on "
     r"the body of base.frame = 'mcr_base::base_link' or one joined to it "
     r"by welds and base.passive_joints alone"),
])
def test_a_description_that_does_not_fit_its_model_names_the_field(
        changes, message):
    with pytest.raises(ValueError, match=message):
        _add(_shipped_text(**changes))


SEVEN_HOME = "home: [0.0, 0.5, 0.3, -0.2, 1.3, 0.2, 0.0]"
SEVEN_ACCELERATIONS = "acceleration_limits: [9.0, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0]"


@pytest.mark.parametrize("old, new, message", [
    (SEVEN_ACCELERATIONS, "acceleration_limits: [9.0, 9.0, 9.0]",
     "arm.acceleration_limits = [9. 9. 9.] has shape (3,), which is not "
     "allowed: must have shape (7,)"),
    (SEVEN_HOME, "home: [0.0, 0.5]",
     "arm.home = [0.  0.5] has shape (2,), which is not allowed: must have "
     "shape (7,)"),
    ("height: 0.35", "height: abc",
     "base.height = 'abc' is not allowed: must be a number"),
    ("footprint_half_sizes: [0.45, 0.35]", "footprint_half_sizes: [a, b]",
     "base.footprint_half_sizes = ['a', 'b'] is not allowed: must be a list "
     "of numbers"),
])
def test_a_description_files_bad_value_is_shown_with_what_is_allowed(
        tmp_path, old, new, message):
    """The loader's errors name the file and the field; a value of the
    wrong shape is shown (it was not), and a field that must be a number
    says so (it said "could not convert string to float: 'abc'")."""
    path = write_omni_arm(tmp_path, 7)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    with pytest.raises(ValueError) as raised:
        load_robot_description(path)
    assert str(raised.value) == f"{path}: {message}"


@pytest.mark.parametrize("old, new, message", [
    ("omni_arm::j7]", "omni_arm::j8]",
     "arm.joints[6] = 'omni_arm::j8' is not allowed: the model has no "
     "joint 'j8' in 'omni_arm'"),
    ("flange_frame: omni_arm::flange", "flange_frame: omni_arm::flangex",
     "arm.flange_frame = 'omni_arm::flangex' is not allowed: the model has "
     "no frame 'flangex' in 'omni_arm'"),
    (SEVEN_HOME, SEVEN_HOME.replace("0.0]", "9.0]"),
     "arm.home[6] = 9.0 is not allowed: must be inside 'omni_arm::j7''s "
     "limits (-2.5, 2.5)"),
    (SEVEN_ACCELERATIONS, SEVEN_ACCELERATIONS + "\n  velocity_limits: "
     "[9.0, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0]",
     "arm.velocity_limits[0] = 9.0 is not allowed: must be within the "
     "model's own 2.0 for 'omni_arm::j1' (a limit may only tighten)"),
])
def test_a_description_that_does_not_fit_its_model_names_its_file(
        tmp_path, old, new, message):
    """The errors of checking a description against its model (joints,
    frames, home, limits: add_robot) start with the description's file,
    as the loader's do (they named the field alone); a description from
    text has no file to name."""
    path = write_omni_arm(tmp_path, 7)
    text = path.read_text()
    assert old in text
    text = text.replace(old, new)
    path.write_text(text)
    description = load_robot_description(path)
    with pytest.raises(ValueError) as raised:
        make_robot_plant(description)
    assert str(raised.value) == f"{path}: {message}"
    assert description.source_file == str(path)
    with pytest.raises(ValueError) as raised:
        make_robot_plant(load_robot_description(text=text, root=tmp_path))
    assert str(raised.value) == message


@pytest.mark.parametrize("given, message", [
    ("file: omni_armX.urdf",
     r"model.file = 'omni_armX.urdf' is not allowed: no such file "
     r"'.*omni_armX.urdf'"),
    ("directives: robot.dmd.yaml",
     r"model.directives = 'robot.dmd.yaml' is not allowed: no such file "
     r"'.*robot.dmd.yaml'"),
    ("file: package://mine/arm.urdf\n  packages: {mine: .}",
     r"model.file = 'package://mine/arm.urdf' is not allowed: no such file "
     r"'.*arm.urdf'"),
    ("file: package://mine/omni_arm.urdf\n  packages: {mine: nowhere}",
     r"model.packages\['mine'\] = 'nowhere' is not allowed: no such folder "
     r"'.*nowhere'"),
])
def test_a_missing_model_file_names_the_field_and_the_description(
        tmp_path, given, message):
    """A model file (or a package's folder) that is not there is an error
    naming the description's file and field and where it was looked for,
    not Drake's parser error naming the path alone."""
    path = write_omni_arm(tmp_path, 6)
    path.write_text(path.read_text().replace("file: omni_arm.urdf", given))
    with pytest.raises(ValueError, match=(
            f"^{re.escape(str(path))}: {message} \\(a relative path is "
            f"relative to the description's folder "
            f"{re.escape(repr(str(tmp_path)))}\\)$")):
        load_robot_description(path)


def test_a_model_file_changed_after_loading_is_checked_when_added(
        tmp_path):
    """A description changed in code after it was loaded (or made there)
    is checked when added to a plant, naming the field, not left to
    Drake's parser."""
    description = load_robot_description(write_omni_arm(tmp_path, 6))
    description.model.file = "gone.urdf"
    with pytest.raises(ValueError, match=(
            rf"^{re.escape(str(tmp_path))}/omni_arm.yaml: "
            r"model.file = 'gone.urdf' is not allowed: no such file "
            r"'.*gone.urdf' \(a relative path is relative to the "
            r"description's folder")):
        make_robot_plant(description)


@pytest.mark.parametrize("file, message", [
    ("package://mine/arm.urdf", r"resolved to '.*arm.urdf' which does not "
     r"exist"),
    ("package://other/omni_arm.urdf", r"refers to unknown package 'other'"),
    ("omni_arm.urdf", r"is invalid")])
def test_a_directives_file_that_does_not_resolve_names_the_field(
        tmp_path, file, message):
    """A file the model directives add that is not there (or a relative
    path, which directives do not take) is an error naming
    model.directives and the model, not Drake's parser error alone
    (for a relative path: 'invalid when parsing a string instead of a
    filename')."""
    path = write_omni_arm(tmp_path, 6)
    (tmp_path / "robot.dmd.yaml").write_text(
        f"directives:\n- add_model: {{name: omni_arm, file: {file}}}\n")
    path.write_text(path.read_text().replace(
        "file: omni_arm.urdf",
        "directives: robot.dmd.yaml\n  packages: {mine: .}"))
    with pytest.raises(ValueError, match=(
            r"model.directives = 'robot.dmd.yaml' is not allowed: its "
            rf"add_model 'omni_arm' gives file = '{file}', which does not "
            rf"resolve \(URI '{file}' {message}.*\); directives name files "
            r"by package:// URLs")):
        make_robot_plant(load_robot_description(path))


@pytest.mark.parametrize("change", ["order", "axis", "floor"])
def test_base_joints_that_are_not_the_bases_pose_are_refused(tmp_path,
                                                             change):
    """The station's odometry reads, and its drivers drive, the base's
    joints as T_b's (x, y, yaw) in the world, T_b on the floor where the
    scene stands: a description listing them in another order, or a
    model turning the base the other way or holding T_b above the floor,
    is refused naming base.joints, not simulated with the base sliding
    sideways or turning against its commands (or its LIDARs slicing the
    scene at the wrong height)."""
    path = write_omni_arm(tmp_path, 6)
    if change == "order":
        path.write_text(path.read_text().replace(
            "[omni_arm::base_x, omni_arm::base_y,",
            "[omni_arm::base_y, omni_arm::base_x,"))
    else:
        urdf = tmp_path / "omni_arm.urdf"
        old, new = {
            "axis": ("<child link='chassis'/><origin xyz='0 0 0'/><axis "
                     "xyz='0 0 1'/>", "<child link='chassis'/><origin "
                     "xyz='0 0 0'/><axis xyz='0 0 -1'/>"),
            "floor": ("<child link='world_x'/><origin xyz='0 0 0'/>",
                      "<child link='world_x'/><origin xyz='0 0 0.1'/>")}[
            change]
        assert old in urdf.read_text()
        urdf.write_text(urdf.read_text().replace(old, new))
    with pytest.raises(ValueError, match=(
            r"base.joints = \[.*\] with base.frame = 'omni_arm::chassis' "
            r"are not allowed: with the joints at \(x, y, yaw\) = "
            r"\(.*\), T_b lies at")):
        make_robot_plant(load_robot_description(path))


@pytest.mark.parametrize("rpy, refused", [
    ("0 0 0.7", False), ("1.5708 0 0", True), ("3.14159 0 0", True)])
def test_a_lidar_frame_whose_z_is_not_up_is_refused(tmp_path, rpy, refused):
    """A scanner scans in its frame's x-y plane, z up, and the station
    simulates it so (at its height and heading in T_b): a frame turned
    otherwise (an optical frame's z forward, or upside down) is refused
    naming lidar_frames, not simulated scanning level."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    urdf.write_text(urdf.read_text().replace(
        "</robot>", "<link name='scanner'/><joint name='scanner' "
        "type='fixed'><parent link='chassis'/><child link='scanner'/>"
        f"<origin xyz='0.4 0.3 0.2' rpy='{rpy}'/></joint>\n</robot>"))
    path.write_text(path.read_text() + "lidar_frames: [omni_arm::scanner]\n")
    description = load_robot_description(path)
    if not refused:
        make_robot_plant(description)
        return
    with pytest.raises(ValueError, match=(
            r"lidar_frames\[0\] = 'omni_arm::scanner' is not allowed: its z "
            r"axis is \[.*\] in T_b \(base.frame\), must be up")):
        make_robot_plant(description)


def test_a_passive_joint_without_a_spring_is_refused(tmp_path):
    """A passive joint of the base with nothing to hold it at rest (a URDF
    joint: URDF has no springs) is refused naming the field, not left to
    fail in the station's static equilibrium with a KeyError."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    old = ("<parent link='chassis'/><child link='link1'/>"
           "<origin xyz='0.2 0 0.4'/>")
    assert old in urdf.read_text()
    urdf.write_text(urdf.read_text().replace(
        old, "<parent link='mount'/><child link='link1'/>"
        "<origin xyz='0 0 0.05'/>").replace(
        "</robot>", "<link name='mount'/><joint name='mount_pitch' "
        "type='revolute'><parent link='chassis'/><child link='mount'/>"
        "<origin xyz='0.2 0 0.35'/><axis xyz='0 1 0'/><limit lower='-0.1' "
        "upper='0.1' effort='0' velocity='1'/></joint>\n</robot>"))
    path.write_text(path.read_text().replace(
        "  velocity_lag: 0.2\n",
        "  velocity_lag: 0.2\n  passive_joints: [omni_arm::mount_pitch]\n"))
    with pytest.raises(ValueError, match=(
            r"base.passive_joints\[0\] = 'omni_arm::mount_pitch' is not "
            r"allowed: it has no spring")):
        make_robot_plant(load_robot_description(path))


def test_a_sensor_frame_not_welded_to_the_sensing_weld_is_refused(
        tmp_path):
    """The wrist sensor measures at its weld (tool.ft_sensor_joint): a
    tool.ft_sensor_frame that a joint of the tool moves against it is
    refused naming the description's fields, not left to the station's
    WeldWrench, whose error named its own argument `frame`."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    old = ("<joint name='tool' type='fixed'><parent link='sensor'/><child "
           "link='tool'/><origin xyz='0 0 0.05'/>")
    assert old in urdf.read_text()
    urdf.write_text(urdf.read_text().replace(old, old.replace(
        "fixed", "revolute") + "<axis xyz='0 0 1'/><limit lower='-1' "
        "upper='1' effort='1' velocity='1'/>"))
    path.write_text(path.read_text().replace(
        "ft_sensor_frame: omni_arm::sensor",
        "ft_sensor_frame: omni_arm::tool"))
    with pytest.raises(ValueError, match=(
            r"tool.ft_sensor_frame = 'omni_arm::tool' is not allowed: must "
            r"be on a body welded to the child of tool.ft_sensor_joint = "
            r"'omni_arm::sensor'")):
        make_robot_plant(load_robot_description(path))


def test_a_joint_in_what_the_sensor_carries_is_refused(tmp_path):
    """The tool outboard of the sensor's weld is compensated as one rigid
    body at the model's rest, and carries the TCP: a joint in it (a
    gripper's, here moving the TCP) loaded, and the controller took the
    tool's weight and the TCP where the joint's rest put them, while the
    station let the joint move."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    old = ("<joint name='tool' type='fixed'><parent link='sensor'/><child "
           "link='tool'/><origin xyz='0 0 0.05'/>")
    urdf.write_text(urdf.read_text().replace(old, old.replace(
        "fixed", "prismatic") + "<axis xyz='1 0 0'/><limit lower='-1' "
        "upper='1' effort='0' velocity='1'/>"))
    with pytest.raises(ValueError, match=(
            r"tool.ft_sensor_joint = 'omni_arm::sensor' is not allowed with "
            r"the prismatic joint 'omni_arm::tool' outboard of it: what the "
            r"wrist sensor carries must be rigid")):
        make_robot_plant(load_robot_description(path))


@pytest.mark.parametrize("name, why", [
    ("omni_arm::j6", "must be a joint that moves \\(not a weld\\) "
     "outboard of tool.ft_sensor_joint"),
    ("omni_arm::tool", "must be a joint that moves \\(not a weld\\)"),
    ("omni_arm::thumb", "no joint"),
])
def test_a_locked_joint_must_move_in_what_the_sensor_carries(tmp_path, name,
                                                             why):
    """tool.locked_joints are the joints the station locks in the tool (a
    gripper's): an arm joint there would freeze the arm in the station,
    a weld is rigid already, and a name not in the model is a typo."""
    path = write_omni_arm(tmp_path, 6)
    path.write_text(path.read_text().replace(
        "ft_sensor_joint: omni_arm::sensor",
        f"ft_sensor_joint: omni_arm::sensor\n  locked_joints: [{name}]"))
    with pytest.raises(ValueError, match=(
            rf"tool.locked_joints\[0\] = '{name}' .*{why}")):
        make_robot_plant(load_robot_description(path))


def test_locked_joints_are_distinct_names():
    with pytest.raises(ValueError, match=(
            r"locked_joints\[1\] = 'a::f' is not allowed: named twice")):
        ToolDescription(tcp_frame="a::t", ft_sensor_frame="a::s",
                        ft_sensor_joint="a::w", ft_sensor_range=[1.0] * 6,
                        locked_joints=["a::f", "a::f"])


def test_a_lidar_beyond_the_bases_passive_joints_is_on_the_base():
    """A scanner on a body the base's passive joints carry (springs, at
    rest in the nominal kinematics) is on the base, as one welded to it;
    the arm's links are not (the description test above)."""
    model = _add(_shipped_text(lidar_frames=["mcr_base::lidar_front_left",
                                             "mcr_base::arm_mount"]))
    assert [f.name() for f in model.lidar_frames] == ["lidar_front_left",
                                                      "arm_mount"]


def test_tighter_limits_are_the_robots_own():
    model = _add(_shipped_text(**{"arm.velocity_limits": [1.0] * 6,
                                  "arm.acceleration_limits": [5.0] * 6}))
    np.testing.assert_array_equal(model.limits.velocity, np.ones(6))
    np.testing.assert_array_equal(model.limits.acceleration, np.full(6, 5.0))


@pytest.mark.parametrize("n", [6, 7])
def test_a_urdf_arm_of_n_joints_gives_its_kinematics(tmp_path, n):
    path = write_omni_arm(tmp_path, n)
    description = load_robot_description(path)
    plant, model = make_robot_plant(description)
    arm = ArmKinematics(plant, model)
    assert arm.num_joints == n
    np.testing.assert_array_equal(arm.acceleration_limits, np.full(n, 9.0))
    np.testing.assert_array_equal(arm.velocity_limits, np.full(n, 2.0))
    rng = np.random.default_rng(4)
    q = rng.uniform(-1.0, 1.0, n)
    values = arm.evaluate(q)
    assert values.J_a.shape == (6, n)
    # The linear rows against central differences of the TCP's position.
    step = 1e-6
    for i in range(n):
        dq = np.zeros(n)
        dq[i] = step
        difference = (arm.evaluate(q + dq).p_ee_in_base
                      - arm.evaluate(q - dq).p_ee_in_base) / (2 * step)
        np.testing.assert_allclose(arm.R_ba @ values.J_a[:3, i], difference,
                                   atol=1e-8)
    context = plant.CreateDefaultContext()
    assert len(joint_position_indices(model.arm_joints)) == n
    assert plant.GetPositions(context).shape == (3 + n,)


def test_a_model_without_acceleration_limits_asks_for_them(tmp_path):
    path = write_omni_arm(tmp_path, 6, accelerations=False)
    with pytest.raises(ValueError, match=(
            r"arm.acceleration_limits\[0\] is missing, which is not "
            r"allowed: the model gives 'omni_arm::j1' none \(inf\)")):
        make_robot_plant(load_robot_description(path))


def _edit_joint(urdf, joint, old, new):
    """Replaces the first `old` after joint `joint`'s tag in file `urdf`
    by `new`."""
    text = urdf.read_text()
    at = text.index(old, text.index(f"<joint name='{joint}'"))
    urdf.write_text(text[:at] + new + text[at + len(old):])


def test_a_zero_speed_limit_in_the_model_is_none(tmp_path):
    """A URDF joint's velocity='0' (what exporters write where nothing
    was set) is no limit: the description must give the joint's speed
    limit, and may, rather than the controller failing on a speed limit
    of 0 that no description could raise."""
    path = write_omni_arm(tmp_path, 6)
    _edit_joint(tmp_path / "omni_arm.urdf", "j1", "velocity='2.0'",
                "velocity='0'")
    with pytest.raises(ValueError, match=(
            r"arm.velocity_limits\[0\] is missing, which is not allowed: "
            r"the model gives 'omni_arm::j1' none \(0.0\)")):
        make_robot_plant(load_robot_description(path))
    path.write_text(path.read_text().replace(
        "  home:", "  velocity_limits: [1.5, 2.0, 2.0, 2.0, 2.0, 2.0]\n"
        "  home:"))
    plant, model = make_robot_plant(load_robot_description(path))
    np.testing.assert_array_equal(model.limits.velocity,
                                  [1.5, 2.0, 2.0, 2.0, 2.0, 2.0])


def test_a_zero_position_range_in_the_model_is_none(tmp_path):
    """A URDF joint's lower = upper = 0 (what exporters write where a
    joint's range was not set) is no position limit: the description must
    give the joint's limits, and may, rather than the home being refused
    inside (0.0, 0.0) and the description's limits as wider than the
    model's; the plant then has them (its joint is not held at 0)."""
    path = write_omni_arm(tmp_path, 6)
    _edit_joint(tmp_path / "omni_arm.urdf", "j2",
                "<limit lower='-2.5' upper='2.5'", "<limit lower='0' upper='0'")
    with pytest.raises(ValueError, match=(
            r"arm.position_lower\[1\] is missing, which is not allowed: "
            r"the model gives 'omni_arm::j2' none \(0.0\)")):
        make_robot_plant(load_robot_description(path))
    path.write_text(path.read_text().replace(
        "  home:", "  position_lower: [-2.5, -2.0, -2.5, -2.5, -2.5, -2.5]\n"
        "  position_upper: [2.5, 2.0, 2.5, 2.5, 2.5, 2.5]\n  home:"))
    plant, model = make_robot_plant(load_robot_description(path))
    np.testing.assert_array_equal(model.limits.lower[:2], [-2.5, -2.0])
    np.testing.assert_array_equal(model.limits.upper[:2], [2.5, 2.0])
    # In the plant too, which would otherwise hold the joint at 0.
    joint = model.arm_joints[1]
    assert (joint.position_lower_limits()[0],
            joint.position_upper_limits()[0]) == (-2.0, 2.0)


def test_an_arm_joint_left_out_of_the_description_is_refused(tmp_path):
    """Six of a seven-joint arm's joints listed: the seventh loaded
    silently, held at its rest in the controller's kinematics (and free
    in the station); every joint between T_a and the TCP is the arm's."""
    path = write_omni_arm(tmp_path, 6)
    (tmp_path / "omni_arm.urdf").write_text(urdf_text(7))
    with pytest.raises(ValueError, match=(
            r"arm.joints = \['omni_arm::j1', .*'omni_arm::j6'\] is not "
            r"allowed: the revolute joint 'omni_arm::j7' between "
            r"arm.base_frame and tool.tcp_frame is not one of them")):
        make_robot_plant(load_robot_description(path))


def test_fewer_than_six_arm_joints_are_refused(tmp_path):
    assert MIN_ARM_JOINTS == 6
    path = write_omni_arm(tmp_path, 5, accelerations=False)
    with pytest.raises(ValueError, match=r"arm.joints = .* at least 6, got 5"):
        load_robot_description(path)


def test_the_controllers_tuning_is_the_robots():
    """A description's tuning is what the capability stage uses on its arm
    where the parameters give none: on the second shipped robot k_j 6e4
    and its band (C_m from the stage equals capability_at with k_j 6e4;
    alpha is 0 at home, above the band); a description without tuning
    gets the paper's."""
    from drake_wbc.math.capability import (
        DEFAULT_JOINT_LIMIT_GAIN,
        CapabilityBand,
    )
    from drake_wbc.robot.tuning import capability_at
    from drake_wbc.stages import ArmCapability

    lbr = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    assert lbr.tuning.joint_limit_gain == 6.0e4
    arm = ArmKinematics(*make_robot_plant(lbr))
    stage = ArmCapability(arm=arm)
    assert stage.band == lbr.tuning.capability_band
    values = stage.evaluate(arm.home)
    assert values[3] == pytest.approx(capability_at(arm, arm.home, 6.0e4),
                                      rel=1e-12)
    assert values[3] > lbr.tuning.capability_band.upper and values[10] == 0
    untuned = load_robot_description(text=_shipped_text(tuning=None),
                                     root=models_dir())
    assert untuned.tuning.joint_limit_gain == DEFAULT_JOINT_LIMIT_GAIN
    assert untuned.tuning.capability_band == CapabilityBand()


def _lbr_on_library_base(folder, arm_url):
    """A description of the second robot's arm (at `arm_url`) on the
    library's omni base, named as a user would: the base and the probe as
    package://drake_wbc/... without mapping that package."""
    (folder / "robot.dmd.yaml").write_text(f"""\
directives:
- add_model: {{name: omni_base_b, file: package://drake_wbc/omni_base_b.sdf}}
- add_model: {{name: lbr7, file: {arm_url}}}
- add_weld: {{parent: omni_base_b::arm_mount, child: lbr7::base_link}}
- add_model: {{name: ft_probe_tool, file: package://drake_wbc/ft_probe_tool.sdf}}
- add_weld: {{parent: lbr7::flange, child: ft_probe_tool::ft_sensor}}
""")
    document = yaml.safe_load(
        (models_dir() / "lbr_omni.robot.yaml").read_text())
    document["model"] = {"directives": "robot.dmd.yaml"}
    return document


def test_a_user_arm_goes_on_the_librarys_base_without_a_path(tmp_path):
    document = _lbr_on_library_base(tmp_path,
                                    "package://drake_wbc/lbr7.sdf")
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(document))
    arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
    assert arm.num_joints == 7


def test_a_descriptions_package_wins_over_one_drake_knows(tmp_path):
    """`drake_models` is a package Drake knows and would download (a
    vendor's URDF refers to its meshes through it); a description that
    maps it to a folder of its own gets that folder, offline."""
    (tmp_path / "drake_models").mkdir()
    (tmp_path / "drake_models" / "arm.sdf").write_text(
        (models_dir() / "lbr7.sdf").read_text())
    document = _lbr_on_library_base(tmp_path,
                                    "package://drake_models/arm.sdf")
    document["model"]["packages"] = {"drake_models": "drake_models"}
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(document))
    arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
    assert arm.num_joints == 7


def test_a_model_drake_cannot_parse_names_the_field(tmp_path):
    """A model file or directives that Drake's parser refuses is a
    ValueError naming the description's field, with the parser's reason
    (it was a RuntimeError from deep in pydrake)."""
    path = write_omni_arm(tmp_path, 6)
    (tmp_path / "omni_arm.urdf").write_text("<robot name='x'><link>")
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: "
                       r"model\.file = 'omni_arm\.urdf' is not allowed: "
                       ".*Failed to parse XML"):
        add_robot(MultibodyPlant(0.001), load_robot_description(path))
    (tmp_path / "arm.dmd.yaml").write_text(
        "directives:\n- add_model: {name: a, file: package://nosuch/a.urdf}\n")
    text = path.read_text().replace("file: omni_arm.urdf",
                                    "directives: arm.dmd.yaml")
    assert "directives: arm.dmd.yaml" in text
    path.write_text(text)
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: "
                       r"model\.directives = 'arm.dmd.yaml' is not allowed: "
                       ".*unknown package"):
        add_robot(MultibodyPlant(0.001), load_robot_description(path))


def test_a_blank_description_with_nan_parts_is_blank():
    """The loader starts from a blank RobotDescription; a blank part holds
    NaN defaults, which are equal only when they are the same object: on
    Python 3.13, whose dataclasses compare field by field, never, and
    every description file was refused ("model is missing"). A blank
    part whose NaN is another object is still blank."""
    blank_base = BaseDescription(height=float("nan"))
    assert RobotDescription(base=blank_base).base is blank_base
    with pytest.raises(ValueError, match="model is missing"):
        RobotDescription(name="r", base=blank_base)
