"""The tuning that depends on the robot (drake_wbc.robot.tuning): k_j, the
capability band and the local workspace, checked and proposed for the
shipped arm and for a 7-joint arm the project did not model."""

import math
import re
import warnings

import numpy as np
import pytest
from omni_arm import write_omni_arm

from drake_wbc.controller import ControllerParameters, build_controller
from drake_wbc.controller.parameters import for_robot
from drake_wbc.math import capability
from drake_wbc.math.capability import CapabilityBand
from drake_wbc.math.workspace import LocalWorkspace, deflection, extent
from drake_wbc.robot.description import load_robot_description, models_dir
from drake_wbc.robot.model import ArmKinematics, make_robot_plant
from drake_wbc.robot.tuning import (
    RobotTuningWarning,
    capability_at,
    check_tuning,
    home_extent,
    mid_range_penalty,
    proposed_joint_limit_gain,
    proposed_local_workspace,
    survey_capability,
)


@pytest.fixture(scope="module")
def shipped():
    return ArmKinematics()


@pytest.fixture(scope="module")
def seven(tmp_path_factory):
    folder = tmp_path_factory.mktemp("seven")
    path = write_omni_arm(folder, 7)
    return ArmKinematics(*make_robot_plant(load_robot_description(path)))


def test_the_proposed_gain_is_ours_on_six_joints_and_scales_with_4_to_the_n():
    assert proposed_joint_limit_gain(6) == pytest.approx(
        capability.DEFAULT_JOINT_LIMIT_GAIN, rel=1e-12)
    assert proposed_joint_limit_gain(7) == pytest.approx(
        4.0 * capability.DEFAULT_JOINT_LIMIT_GAIN, rel=1e-12)
    # With every joint mid-range (each factor 1/4), P_jnt from its formula.
    q = np.zeros(7)
    lower, upper = -np.ones(7), np.ones(7)
    for n, k_j in ((6, 1.5e4), (7, 1.5e4), (7, proposed_joint_limit_gain(7))):
        assert capability.joint_limit_penalty(
            q[:n], lower[:n], upper[:n], k_j) == pytest.approx(
                mid_range_penalty(k_j, n), rel=1e-12)
    assert mid_range_penalty(1.5e4, 7) == pytest.approx(
        1.0 - math.exp(-1.5e4 / 4**7))
    assert mid_range_penalty(1.5e4, 7) < 0.61


def test_the_shipped_robot_is_tuned_and_its_proposal_is_the_papers_band(
        shipped):
    assert check_tuning(shipped, CapabilityBand(),
                        capability.DEFAULT_JOINT_LIMIT_GAIN) == []
    survey = survey_capability(shipped, count=200)
    band = survey.proposed_band()
    assert band.lower == pytest.approx(0.035, rel=2e-3)
    assert band.upper == pytest.approx(0.04, rel=2e-3)
    assert survey.home == pytest.approx(capability_at(
        shipped, shipped.home, capability.DEFAULT_JOINT_LIMIT_GAIN))
    assert 0.0 < survey.fraction_below(band.lower) < 1.0


def test_a_band_active_at_home_says_what_to_change(shipped):
    home = capability_at(shipped, shipped.home,
                         capability.DEFAULT_JOINT_LIMIT_GAIN)
    problems = check_tuning(shipped, CapabilityBand(0.06, 0.07),
                            capability.DEFAULT_JOINT_LIMIT_GAIN)
    assert len(problems) == 1
    assert "capability_band = (0.06, 0.07) is active at the robot's home" \
        in problems[0]
    assert f"{home:.4g}" in problems[0]


def test_a_singular_home_is_named_and_no_band_is_proposed_there(
        tmp_path, capsys):
    """An arm whose home is stretched straight (every joint at 0: J_a
    loses a rank, C_m = 0), or 1e-8 rad from it, is told to bend its
    home, instead of being proposed the band (0, 0), which `drake-wbc
    demo` crashed on, or one of 1e-10; a home is singular for the tuning
    where s_min of J_a is below the arm controller's damping threshold
    (there its damped least squares gives way), by SVD."""
    from drake_wbc.cli.main import main
    from drake_wbc.math.arm_control import DEFAULT_DAMPING_THRESHOLD
    from drake_wbc.robot.tuning import singular, smallest_singular_value

    path = write_omni_arm(tmp_path, 6)
    text = path.read_text()
    home = text[text.index("home: ["):].split("\n", 1)[0]
    for stretched in ("[0, 0, 0, 0, 0, 0]", "[0, 0, 1.0e-8, 0, 0, 0]"):
        path.write_text(text.replace(home, f"home: {stretched}"))
        arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
        assert singular(arm)
        assert capability_at(arm, arm.home, 1.5e4) < 1e-9
        problems = check_tuning(arm, CapabilityBand(), 1.5e4)
        assert len(problems) == 1
        assert problems[0].startswith(
            f"arm.home = {arm.home.tolist()} is at or near a singularity")
        assert main(["demo", "--robot", str(path), "--output",
                     str(tmp_path)]) == 0
        out = capsys.readouterr().out
        assert ("proposed capability_band: none, the home is at or near a "
                "singularity") in out
        assert f"arm.home = {arm.home.tolist()} is at or near" in out
    # The same arm at other joints: its usual home (s_min 0.15) is not
    # singular; a slightly bent arm is what its s_min says.
    good = np.array([0.0, 0.8, 1.1, -0.4, -1.2, 0.3])
    assert not singular(arm, good)
    for q in (good, np.array([0.0, 0.05, 0.05, 0.0, 0.05, 0.0])):
        s_min = np.linalg.svd(arm.evaluate(q).J_a, compute_uv=False)[-1]
        assert smallest_singular_value(arm, q) == s_min
        assert singular(arm, q) == (s_min < DEFAULT_DAMPING_THRESHOLD)


@pytest.mark.parametrize("j7", [2.4, 2.45])
def test_the_band_to_give_is_the_one_at_the_proposed_k_j(tmp_path, capsys,
                                                         j7):
    """`drake-wbc demo` on a 7-joint arm with no tuning, its home with
    the last joint near its limit (C_m at home 0.0175 with the six-joint
    k_j = 1.5e4, 0.065 with the proposed 6e4; with j7 = 2.45, 0.009 and
    0.035): it proposes k_j and a band at that k_j, and its "to change"
    sentence about the band is at that k_j too. It suggested a second
    band at the old k_j ((0.00946, 0.0108) beside the proposed (0.0352,
    0.0402)); now the band (0.035, 0.04), not active at home with the
    proposed k_j, is not to change, and where it still is (j7 = 2.45)
    the band to give is the proposed one, said to be at that k_j."""
    from drake_wbc.cli.main import main

    path = write_omni_arm(tmp_path, 7)
    text = path.read_text()
    home = text[text.index("home: ["):].split("\n", 1)[0]
    path.write_text(text.replace(
        home, f"home: [0.0, 0.5, 0.3, -0.2, 1.3, 0.2, {j7}]"))
    arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
    k_j = proposed_joint_limit_gain(7)
    at_proposed = capability_at(arm, arm.home, k_j)
    assert capability_at(arm, arm.home, 1.5e4) < 0.035
    assert main(["demo", "--robot", str(path), "--output",
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out
    proposed = re.search(r"proposed capability_band: \(([^,]+), ([^)]+)\)",
                         out)
    lower, upper = 0.035 / 0.0649 * at_proposed, 0.04 / 0.0649 * at_proposed
    assert proposed.groups() == (f"{lower:.4g}", f"{upper:.4g}")
    to_give = re.findall(r"give a band below it, e\.g\. \(([^,]+), "
                         r"([^)]+)\)", out)
    if at_proposed > 0.04:
        assert to_give == []
    else:
        assert to_give == [(f"{lower:.3g}", f"{upper:.3g}")]
        assert (f"where C_m = {at_proposed:.4g} with the proposed k_j = "
                "6e+04") in out


def test_a_seven_joint_arm_with_the_six_joint_tuning_is_warned_of(seven):
    problems = check_tuning(seven, CapabilityBand(),
                            capability.DEFAULT_JOINT_LIMIT_GAIN)
    assert any("caps P_jnt at 0.60 on this arm's 7 joints" in p
               for p in problems)
    with pytest.warns(RobotTuningWarning, match="caps P_jnt"):
        build_controller(ControllerParameters(), robot=seven)
    # Its proposed tuning builds without a word.
    survey = survey_capability(seven, count=100)
    params = ControllerParameters()
    params.capability.joint_limit_gain = survey.k_j
    params.capability_band = survey.proposed_band()
    assert check_tuning(seven, params.capability_band, survey.k_j) == []
    with warnings.catch_warnings():
        warnings.simplefilter("error", RobotTuningWarning)
        build_controller(params, robot=seven)


def test_the_local_workspace_is_proposed_and_checked_at_the_arms_home(
        shipped, seven):
    """The proposal is the paper's d^l, d^u on the shipped arm (its tool
    0.736 m out at home) and scales with another arm's home extent (the
    omni arm's, about 1 m, by the TCP's position in T_a); the paper's
    extents on that arm, within its home, are a problem naming
    extent_lower, warned of in the intuitive pHRI mode only."""
    own = proposed_local_workspace(shipped)
    assert (own.extent_lower, own.extent_upper) == pytest.approx(
        (0.75, 0.8), abs=1e-4)
    assert (own.deflection_lower, own.deflection_upper) == (
        LocalWorkspace().deflection_lower, LocalWorkspace().deflection_upper)
    band, k_j = CapabilityBand(), capability.DEFAULT_JOINT_LIMIT_GAIN
    assert check_tuning(shipped, band, k_j, LocalWorkspace()) == []
    d = extent(seven.evaluate(seven.home).pose[:3, 3])
    assert home_extent(seven) == d > 0.8
    proposal = proposed_local_workspace(seven)
    assert proposal.extent_lower == pytest.approx(0.75 / 0.7358 * d)
    assert proposal.extent_upper == pytest.approx(0.8 / 0.7358 * d)
    k_j = proposed_joint_limit_gain(7)
    band = survey_capability(seven, count=100).proposed_band()
    problems = check_tuning(seven, band, k_j, LocalWorkspace())
    assert len(problems) == 1
    assert "workspace.workspace.extent_lower = 0.75 m" in problems[0]
    assert f"d = {d:.4g} m" in problems[0]
    assert check_tuning(seven, band, k_j, proposal) == []
    params = ControllerParameters()
    params.capability.joint_limit_gain, params.capability_band = k_j, band
    with warnings.catch_warnings():
        warnings.simplefilter("error", RobotTuningWarning)
        build_controller(params, robot=seven)  # loco-manipulation
    params.workspace.mode = "intuitive-phri"
    with pytest.warns(RobotTuningWarning, match="extent_lower"):
        build_controller(params, robot=seven)


@pytest.mark.parametrize("name", ["lbr_omni", "ur_omni"])
def test_the_shipped_robots_carry_the_tuning_their_demo_proposes(name):
    """The second and third shipped robots' descriptions hold what
    `drake-wbc demo --robot` proposes for their arms, to the three
    decimals written: k_j for their number of joints, the band at 0.54
    and 0.62 of C_m at home and, where the tool at home reaches beyond
    the paper's d^l (the UR-class arm's, 0.752 m), the local workspace
    at that reach; check_tuning finds nothing to change."""
    robot = load_robot_description(models_dir() / f"{name}.robot.yaml")
    arm = ArmKinematics(*make_robot_plant(robot))
    tuning = robot.tuning
    assert tuning.joint_limit_gain == pytest.approx(
        proposed_joint_limit_gain(arm.num_joints), rel=1e-9)
    band = survey_capability(arm, count=1).proposed_band()
    assert (tuning.capability_band.lower, tuning.capability_band.upper) == (
        pytest.approx((band.lower, band.upper), abs=5e-4))
    workspace = tuning.local_workspace
    if home_extent(arm) > LocalWorkspace().extent_lower:
        proposal = proposed_local_workspace(arm)
        assert (workspace.extent_lower, workspace.extent_upper) == (
            pytest.approx((proposal.extent_lower, proposal.extent_upper),
                          abs=5e-4))
    else:
        assert workspace == LocalWorkspace()
    assert check_tuning(arm, tuning.capability_band,
                        tuning.joint_limit_gain, workspace) == []


def test_an_arm_base_frame_facing_away_from_the_tool_is_warned_of(tmp_path):
    """An arm whose base frame's x axis points away from where the arm
    reaches at home (a UR's base_link, turned by pi from its base): the
    tool at home lies beyond the local workspace's deflection, where the
    intuitive pHRI mode hands all planar motion to the base from the
    start; check_tuning says so, naming deflection_lower, even with
    extents that suit the arm."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    urdf.write_text(urdf.read_text().replace(
        "<parent link='chassis'/><child link='link1'/>"
        "<origin xyz='0.2 0 0.4'/>",
        "<parent link='arm_base'/><child link='link1'/>"
        "<origin xyz='0 0 0.05' rpy='0 0 3.141592653589793'/>").replace(
        "</robot>", "<link name='arm_base'/><joint name='arm_mount' "
        "type='fixed'><parent link='chassis'/><child link='arm_base'/>"
        "<origin xyz='0.2 0 0.35' rpy='0 0 3.141592653589793'/></joint>"
        "\n</robot>"))
    path.write_text(path.read_text().replace(
        "  base_frame: omni_arm::chassis\n  flange_frame",
        "  base_frame: omni_arm::arm_base\n  flange_frame"))
    arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
    assert deflection(arm.evaluate(arm.home).pose[:3, 3]) > 0.9 * math.pi
    band = survey_capability(arm, count=100).proposed_band()
    problems = check_tuning(arm, band, capability.DEFAULT_JOINT_LIMIT_GAIN,
                            proposed_local_workspace(arm))
    assert len(problems) == 1
    assert "workspace.workspace.deflection_lower" in problems[0]
    assert "arm.base_frame" in problems[0]


def test_a_descriptions_local_workspace_is_the_controllers(tmp_path):
    """tuning.local_workspace in the description is what the controller's
    parameters take where they give none; a given one is kept."""
    path = write_omni_arm(tmp_path, 7)
    path.write_text(path.read_text() + (
        "tuning:\n  local_workspace: {extent_lower: 1.1, extent_upper: 1.2}"
        "\n"))
    robot = load_robot_description(path)
    assert robot.tuning.local_workspace == LocalWorkspace(1.1, 1.2)
    assert for_robot(ControllerParameters(), robot).workspace.workspace == (
        LocalWorkspace(1.1, 1.2))
    params = ControllerParameters()
    params.workspace.workspace = LocalWorkspace(0.9, 1.0)
    assert for_robot(params, robot).workspace.workspace == LocalWorkspace(
        0.9, 1.0)
    path.write_text(path.read_text().replace("extent_upper: 1.2",
                                             "extent_upper: 1.0"))
    with pytest.raises(ValueError, match="extent_upper"):
        load_robot_description(path)


def test_a_scenario_starting_away_from_home_is_warned_of_its_start():
    """The pHRI scenario started with the elbow opened 0.2 rad (the tool
    0.765 m out, beyond d^l = 0.75) is warned that the base takes the
    motion from the start, naming the start; started stretched straight
    (singular), that its start is singular; at home, nothing."""
    from drake_wbc.experiments.scenario import find_scenario, load_scenario

    text = find_scenario("phri").read_text()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_scenario(text=text)
    home = ArmKinematics().home.tolist()
    opened = home[:2] + [home[2] - 0.2] + home[3:]
    wider = home[:2] + [home[2] - 0.5] + home[3:]
    for start, expected in (
            (opened, "workspace.workspace.extent_lower = 0.75 m is within "
                     "the tool's extent at the start "
                     "(station.initial_arm_positions), d = 0.7651 m: in "
                     "the intuitive pHRI mode the base would take the "
                     "motion from the start; start nearer the home, or "
                     "give extents beyond it, e.g. (0.78, 0.832)"),
            (wider, "capability_band = (0.035, 0.04) is active at the "
                    "start (station.initial_arm_positions), where C_m = "
                    "0.03305: the compensation would give way and k_n "
                    "switch off from the start; start nearer the home, or "
                    "give a band below it, e.g. (0.0178, 0.0204)"),
            ([0.0] * 6, "station.initial_arm_positions = [0.0, 0.0, 0.0, "
                        "0.0, 0.0, 0.0] is at or near a singularity")):
        with pytest.warns(RobotTuningWarning) as record:
            load_scenario(text=text.replace(
                "\nstation:\n",
                f"\nstation:\n  initial_arm_positions: {start}\n"))
        assert any(str(w.message).startswith(expected) for w in record), [
            str(w.message) for w in record]
    # Put on its own robot again (--robot with the shipped file), the
    # scenario warns no more: it said so when it loaded.
    from drake_wbc.experiments.scenario import robot_file_of, with_robot

    with pytest.warns(RobotTuningWarning):
        scenario = load_scenario(text=text.replace(
            "\nstation:\n", f"\nstation:\n  initial_arm_positions: "
            f"{opened}\n"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with_robot(scenario, robot_file_of(scenario), echo=None)
