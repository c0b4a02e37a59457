"""An arm with continuous joints (no position limits, URDF's
type="continuous", -inf and inf in Drake): the seven-joint omni arm of
tests/omni_arm.py with its joints 1, 3, 5 and 7 continuous, as a
Gen3-class arm has them. An infinite range is no position limit, in
every part from the description to the closed loop, while the speed and
acceleration limits hold; a joint limited on one side only is refused."""

import math

import numpy as np
import pytest
from omni_arm import HOMES, write_omni_arm, write_scenario
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.systems.primitives import Linearize

from drake_wbc.bench.distribution_race import make_problems
from drake_wbc.experiments.runner import build_closed_loop, start_simulator
from drake_wbc.experiments.scenario import load_scenario
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.hardware.safety import Limits, follow_arm_command
from drake_wbc.math import arm_control, capability
from drake_wbc.math.arm_control import ArmControllerParameters
from drake_wbc.math.arm_servo import arm_command_violation, brake_speed
from drake_wbc.math.joint_range import ONE_TURN, configuration_range
from drake_wbc.math.validation import ordered_limits
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.model import ArmKinematics, make_robot_plant
from drake_wbc.robot.tuning import survey_capability
from drake_wbc.stages import ArmCartesianVelocityController
from drake_wbc.stages.capability_stage import ArmCapability

CONTINUOUS = (0, 2, 4, 6)
"""The continuous joints of the arm (0 the first), a Gen3's 1, 3, 5, 7."""

INF = math.inf


def _arm(folder, continuous=CONTINUOUS, extra=""):
    path = write_omni_arm(folder, 7, continuous=continuous, extra=extra)
    return ArmKinematics(*make_robot_plant(load_robot_description(path)))


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    return _arm(tmp_path_factory.mktemp("continuous"))


def _free():
    free = np.zeros(7, dtype=bool)
    free[list(CONTINUOUS)] = True
    return free


# --- the robot as data -------------------------------------------------------


def test_a_continuous_joint_has_no_position_limits(arm):
    """Its limits are the model's -inf and inf (they were refused as
    missing, asking the description for finite ones); the limited joints
    keep theirs, and the speed and acceleration limits hold on all."""
    free = _free()
    np.testing.assert_array_equal(arm.lower[free], -INF)
    np.testing.assert_array_equal(arm.upper[free], INF)
    np.testing.assert_array_equal(arm.lower[~free], -2.5)
    np.testing.assert_array_equal(arm.upper[~free], 2.5)
    np.testing.assert_array_equal(arm.velocity_limits, np.full(7, 2.0))
    np.testing.assert_array_equal(arm.acceleration_limits, np.full(7, 9.0))


def test_the_description_may_keep_or_limit_a_continuous_joint(tmp_path):
    """-.inf and .inf keep a continuous joint unlimited while another is
    tightened; finite ones limit it (a tightening); an infinity where the
    model has a limit widens it and is refused, as is a pair infinite
    on one side only, naming the joint and its limits."""
    lower = [-.5, -2.0, "-.inf", -2.5, "-.inf", -2.5, "-.inf"]
    upper = [.5, 2.0, ".inf", 2.5, ".inf", 2.5, ".inf"]

    def limits(lower, upper):
        return (f"  position_lower: [{', '.join(map(str, lower))}]\n"
                f"  position_upper: [{', '.join(map(str, upper))}]")

    arm = _arm(tmp_path, extra=limits(lower, upper))
    np.testing.assert_array_equal(arm.lower, [-.5, -2.0, -INF, -2.5, -INF,
                                              -2.5, -INF])
    np.testing.assert_array_equal(arm.upper, [.5, 2.0, INF, 2.5, INF, 2.5,
                                              INF])
    wider = lower.copy()
    wider[1] = "-.inf"
    with pytest.raises(ValueError, match=(
            r"arm.position_lower\[1\] = -inf is not allowed: must be within "
            r"the model's own -2.5 for 'omni_arm::j2'")):
        _arm(tmp_path, extra=limits(wider, upper))
    one_sided = upper.copy()
    one_sided[2] = 1.0
    with pytest.raises(ValueError, match=(
            r"arm.position_lower\[2\] = -inf and arm.position_upper\[2\] = "
            r"1.0 \(the model gives -inf and inf\) are not allowed for "
            r"'omni_arm::j3': a joint is limited on both sides, or on "
            r"neither")):
        _arm(tmp_path, extra=limits(lower, one_sided))
    with pytest.raises(ValueError, match=(
            r"position_upper\[2\] = -inf is not allowed: must be finite, "
            r"or inf")):
        _arm(tmp_path, extra=limits(lower, [*upper[:2], "-.inf",
                                            *upper[3:]]))


def test_limits_infinite_on_one_side_are_refused_where_they_enter():
    with pytest.raises(ValueError, match=(
            r"lower\[1\] = -inf and upper\[1\] = 2.0 are not allowed: each "
            r"pair must be finite, or -inf and inf together")):
        ordered_limits("lower", [-1.0, -INF], "upper", [1.0, 2.0],
                       unlimited=True)
    with pytest.raises(ValueError, match="every entry must be finite"):
        ordered_limits("lower", [-INF], "upper", [INF])
    lower, upper = ordered_limits("lower", [-INF, -1.0], "upper",
                                  [INF, 1.0], unlimited=True)
    np.testing.assert_array_equal(upper, [INF, 1.0])
    with pytest.raises(ValueError, match=r"lower\[0\] = -inf and upper"):
        ArmControllerParameters(lower=[-INF] * 6, upper=[2.0] * 6)
    assert ArmControllerParameters(lower=[-INF] * 6,
                                   upper=[INF] * 6).upper == (INF,) * 6


# --- the closed loop --------------------------------------------------------


def _run(folder, continuous, duration=3.0):
    folder.mkdir()
    robot = write_omni_arm(folder, 7, continuous=continuous)
    loop = build_closed_loop(load_scenario(write_scenario(folder, robot,
                                                          duration)))
    simulator = start_simulator(loop)
    root = simulator.get_mutable_context()
    station = loop.station.diagram
    context = station.GetMyContextFromRoot(root)
    pose = station.GetOutputPort("truth.end_effector_pose")
    command = station.GetInputPort("arm.position_command")
    path, commands = [], []
    for t in np.arange(0.25, duration + 1e-9, 0.25):
        simulator.AdvanceTo(t)
        path.append(pose.Eval(context)[:3].copy())
        commands.append(command.Eval(context).copy())
    return np.array(path), np.array(commands), loop.controller.safety_reason(
        root)


def test_the_closed_loop_of_a_continuous_joint_arm_tracks(tmp_path):
    """The simulated station (a MultibodyPlant of the URDF, its drivers,
    the arm servo that faults on a limit) and the controller track the
    world twist [0.05, 0, 0.02] m/s for 3 s with joints 1, 3, 5, 7
    continuous, as the same arm with them limited to +-2.5 rad does: far
    from every limit the tool's paths differ by under 0.5 mm (the
    joint-limit penalty's factors of those joints, 1/4 against about
    0.24, turn the null-space term a little; and the joints differ in
    the self-motion, which centres a limited joint and leaves a
    continuous one). Nothing is NaN, and nothing stops."""
    limited, _, reason = _run(tmp_path / "limited", ())
    assert reason == ""
    path, commands, reason = _run(tmp_path / "continuous", CONTINUOUS)
    assert reason == ""
    assert np.all(np.isfinite(path)) and np.all(np.isfinite(commands))
    moved = path[-1] - path[1]  # from 0.5 s to 3 s: 2.5 s of the twist
    assert moved[0] == pytest.approx(2.5 * 0.05, rel=0.05)
    assert moved[2] == pytest.approx(2.5 * 0.02, rel=0.1)
    assert abs(moved[1]) < 1e-3
    assert np.max(np.abs(path - limited)) < 5e-4


# The test arm is not tuned (drake-wbc demo would propose k_j and the
# workspace): the stress case's invariants are the point here.
@pytest.mark.filterwarnings(
    "ignore::drake_wbc.robot.tuning.RobotTuningWarning")
def test_a_stress_case_of_an_arm_without_position_limits_holds(tmp_path):
    """`drake-wbc stress --robot` on an arm of continuous joints alone: a
    case's joint limit margins are None (no limit to measure to), as a
    distance is without obstacles, not inf, which failed every case as
    a number that is not finite; the case breaks no invariant."""
    from drake_wbc.stress.cases import run_case, violations
    from drake_wbc.stress.run import summary_table

    robot = write_omni_arm(tmp_path, 7, continuous=range(7))
    record = run_case(0, 0, 0.3, str(robot))
    assert record["error"] == ""
    assert record["min_joint_limit_margin_rad"] is None
    assert record["min_command_joint_limit_margin_rad"] is None
    assert record["all_finite"] and record["arm_fault"] == "none"
    assert violations(record) == []
    assert summary_table([record]).splitlines()[-1].endswith("  ok")


# --- each function that meets an infinite range ---------------------------


def test_the_joint_limit_penalty_of_a_continuous_joint_is_mid_ranges(arm):
    """P_jnt = 1 - exp(-k_j 4^-4 prod f_i) over the limited joints (each
    continuous one's factor 1/4, its slope 0: the limit as its range
    grows), at any angle of the continuous joints; was NaN (inf / inf)
    or refused."""
    k_j = 6.0e4
    free = _free()
    for turns in (0.0, 1.0, -3.0):
        q = np.array(HOMES[7]) + np.where(free, 2.0 * np.pi * turns, 0.0)
        q_l = q[~free]
        factors = (q_l + 2.5) * (2.5 - q_l) / 25.0
        expected = -math.expm1(-k_j * 0.25**4 * np.prod(factors))
        assert capability.joint_limit_penalty(
            q, arm.lower, arm.upper, k_j) == pytest.approx(expected,
                                                           rel=1e-14)
        gradient = capability.joint_limit_penalty_gradient(
            q, arm.lower, arm.upper, k_j)
        np.testing.assert_array_equal(gradient[free], 0.0)
        # The limit of a range grown about the joint: the same to 1e-10.
        wide = np.where(free, 1e6, 2.5)
        np.testing.assert_allclose(
            gradient, capability.joint_limit_penalty_gradient(
                q, -wide + np.where(free, q, 0.0),
                wide + np.where(free, q, 0.0), k_j), rtol=0, atol=1e-10)
        J = arm.evaluate(q).J_a
        C_m, g = capability.capability_terms_float(
            J, q, arm.lower, arm.upper, k_j, 0.02, 0.02)
        reference = capability.capability_terms(J, q, arm.lower, arm.upper,
                                                k_j, 0.02, 0.02)
        assert C_m == pytest.approx(capability.manipulability(J) * expected,
                                    rel=1e-12)
        assert C_m == pytest.approx(reference[0], rel=1e-12)
        np.testing.assert_allclose(g, reference[1], rtol=0, atol=1e-12)


def test_a_joint_of_finite_limits_is_limited_however_wide(arm):
    """A joint limited to (-1e200, 1) at 0.5, beside a continuous one, is
    a limited joint 0.5 rad from its upper limit: its factor (0.5 +
    1e200) 0.5 / (1 + 1e200)^2, some 5e-201, makes P_jnt about k_j
    prod_i f_i, some 1e-200, and C_m and their gradients as small, in
    both bodies. Its range's square overflows to inf, which took it for a
    continuous joint before (P_jnt 0.45 here)."""
    k_j = 1e4
    q = np.array(HOMES[7])
    q[1] = 0.5
    lower, upper = arm.lower.copy(), arm.upper.copy()
    lower[1], upper[1] = -1e200, 1.0
    assert math.isinf(lower[0])  # and joint 0 continuous
    factors = [0.25 if math.isinf(low) else
               ((q_i - low) / (high - low)) * ((high - q_i) / (high - low))
               for q_i, low, high in zip(q, lower, upper, strict=True)]
    expected = k_j * math.prod(factors)  # 1 - exp(-x) = x to rounding here
    assert 1e-201 < expected < 1e-199
    penalty = capability.joint_limit_penalty(q, lower, upper, k_j)
    assert penalty == pytest.approx(expected, rel=1e-12)
    assert np.all(np.abs(capability.joint_limit_penalty_gradient(
        q, lower, upper, k_j)) < 1e-190)
    J = arm.evaluate(q).J_a
    C_m, g = capability.capability_terms_float(J, q, lower, upper, k_j,
                                               0.02, 0.02)
    assert C_m == pytest.approx(capability.manipulability(J) * penalty,
                                rel=1e-12)
    assert np.all(np.abs(g) < 1e-190)


def test_a_range_whose_square_overflows_is_mid_range_at_its_middle(arm):
    """A joint limited to (-1e200, 1e200) at 0 is at mid-range: its factor
    (q - l)(u - q) / (u - l)^2 is 1/4, so P_jnt, C_m and their gradients
    are those of the same arm with that joint continuous, in both bodies,
    with no overflow on the way (the product of the two distances is
    1e400: inf / inf was NaN)."""
    k_j = 1e4
    q = np.array(HOMES[7])
    q[1] = 0.0
    lower, upper = arm.lower.copy(), arm.upper.copy()
    lower[1], upper[1] = -1e200, 1e200
    continuous_lower, continuous_upper = lower.copy(), upper.copy()
    continuous_lower[1], continuous_upper[1] = -np.inf, np.inf
    J = arm.evaluate(q).J_a
    with np.errstate(all="raise"):
        penalty = capability.joint_limit_penalty(q, lower, upper, k_j)
        gradient = capability.joint_limit_penalty_gradient(q, lower, upper,
                                                           k_j)
        fast = capability.capability_terms_float(J, q, lower, upper, k_j,
                                                 0.02, 0.02)
        reference = capability.capability_terms(J, q, lower, upper, k_j,
                                                0.02, 0.02)
    assert penalty == pytest.approx(capability.joint_limit_penalty(
        q, continuous_lower, continuous_upper, k_j), rel=1e-14)
    np.testing.assert_allclose(
        gradient, capability.joint_limit_penalty_gradient(
            q, continuous_lower, continuous_upper, k_j),
        rtol=1e-12, atol=1e-300)
    expected = capability.capability_terms_float(
        J, q, continuous_lower, continuous_upper, k_j, 0.02, 0.02)
    for C_m, g in (fast, reference):
        assert C_m == pytest.approx(expected[0], rel=1e-14)
        np.testing.assert_allclose(g, expected[1], rtol=1e-12, atol=1e-15)


def test_the_capability_of_a_continuous_joint_arm_in_autodiff(arm):
    """C_m's reference body in AutoDiffXd: its value the float one's and
    its derivatives dC_m/dq (P_jnt dm/dq + m dP_jnt/dq), finite."""
    q = np.array(HOMES[7])
    q_ad = InitializeAutoDiff(q).ravel()
    J = arm.evaluate(q).J_a
    penalty = capability._joint_limit_penalty(q_ad, arm.lower, arm.upper,
                                              6.0e4)
    assert isinstance(penalty, AutoDiffXd)
    assert penalty.value() == pytest.approx(capability.joint_limit_penalty(
        q, arm.lower, arm.upper, 6.0e4), rel=1e-14)
    np.testing.assert_allclose(
        penalty.derivatives(), capability.joint_limit_penalty_gradient(
            q, arm.lower, arm.upper, 6.0e4), rtol=1e-12, atol=0)
    C_m, g = capability.capability_terms(J, q_ad, arm.lower, arm.upper,
                                         6.0e4, 0.02, 0.02)
    assert np.all(np.isfinite(C_m.derivatives()))
    assert all(np.all(np.isfinite(v.derivatives())) for v in g)


def test_the_arm_controller_has_no_position_bound_on_a_continuous_joint():
    """No bound at all (+-inf) towards a continuous joint's missing edges,
    at any angle, with and without the acceleration limit (braking_rate
    of an infinite distance raised OverflowError); the limited joint
    keeps its bound, as with the other's limits finite."""
    q = np.array([40.0, 2.4])
    lower, upper = np.array([-INF, -2.5]), np.array([INF, 2.5])
    for acceleration in (None, 9.0):
        low, high = arm_control.joint_position_velocity_bounds(
            q, lower, upper, 0.01, 0.05, acceleration)
        np.testing.assert_array_equal([low[0], high[0]], [-INF, INF])
        finite = arm_control.joint_position_velocity_bounds(
            q, [-50.0, -2.5], [50.0, 2.5], 0.01, 0.05, acceleration)
        assert (low[1], high[1]) == (finite[0][1], finite[1][1])


@pytest.mark.parametrize("acceleration", [None, 9.0])
def test_a_continuous_joint_is_commanded_as_one_far_from_its_limits(
        arm, acceleration):
    """joint_velocity_for_twist on the seven-joint arm with its
    continuous joints many turns from home: the same command as with
    their limits 1e3 rad away (where no bound acts and the self-motion's
    centring, k_c (q - m) / r, is 1e-3 of a limit's), to 1e-3 of the
    speed limit, in the reference and the float kernel alike; no
    NaN. The centring of a continuous joint is 0 (was (q - nan) / inf)."""
    free = _free()
    q = np.array(HOMES[7]) + np.where(free, 20.0 * np.pi, 0.0)
    J = arm.evaluate(q).J_a
    V = np.array([0.3, -0.1, 0.2, 0.0, 0.4, -0.2])
    far = np.where(free, 1e3, 2.5)
    centre = np.where(free, q, 0.0)
    np.testing.assert_array_equal(arm_control.centring_velocity(
        q, arm.lower, arm.upper, 0.5)[free], 0.0)
    args = dict(velocity_limit=arm.velocity_limits, time_step=0.01,
                acceleration_limit=acceleration,
                previous_q_dot=None if acceleration is None else np.zeros(7))
    command = arm_control.joint_velocity_for_twist(J, V, q, arm.lower,
                                                   arm.upper, **args)
    within = arm_control.joint_velocity_for_twist(
        J, V, q, centre - far, centre + far, **args)
    assert np.all(np.isfinite(command.q_dot))
    np.testing.assert_allclose(command.q_dot, within.q_dot, rtol=0,
                               atol=2e-3)
    assert not command.limited_joints[free].any()
    limits = arm_control.twist_limits(
        arm.lower, arm.upper, arm.velocity_limits, 0.01,
        acceleration_limit=acceleration,
        self_motion_gain=arm_control.DEFAULT_SELF_MOTION_GAIN)
    previous = np.zeros(7)
    reference = arm_control.joint_velocity_command(J, V, q, previous, limits)
    kernel = arm_control.joint_velocity_command_float(J, V, q, previous,
                                                      limits)
    np.testing.assert_allclose(kernel.q_dot, reference.q_dot, rtol=0,
                               atol=1e-12)
    assert np.all(np.isfinite(kernel.q_dot))


def test_the_arm_controller_in_autodiff_with_a_continuous_joint(arm):
    """The reference body in AutoDiffXd (the stage's linearisation): the
    float value, finite derivatives."""
    q = np.array(HOMES[7])
    J = arm.evaluate(q).J_a
    V = InitializeAutoDiff(np.array([0.1, 0.0, 0.05, 0.0, 0.0, 0.1])
                           ).ravel()
    limits = arm_control.twist_limits(
        arm.lower, arm.upper, arm.velocity_limits, 0.01,
        acceleration_limit=arm.acceleration_limits,
        self_motion_gain=arm_control.DEFAULT_SELF_MOTION_GAIN)
    previous = np.zeros(7)
    result = arm_control.joint_velocity_command(J, V, q, previous, limits)
    values = np.array([v.value() for v in result.q_dot])
    np.testing.assert_allclose(values, arm_control.joint_velocity_command(
        J, np.array([0.1, 0.0, 0.05, 0.0, 0.0, 0.1]), q, previous,
        limits).q_dot, rtol=0, atol=1e-14)
    assert all(np.all(np.isfinite(v.derivatives())) for v in result.q_dot)


def test_brake_speed_towards_no_limit_is_unbounded():
    """brake_speed of an infinite distance (towards a continuous joint's
    missing limit) is inf; was NaN (inf - inf), which made every command
    of the robot side's limiter NaN."""
    speed = brake_speed(np.array([INF, 0.3]), np.array([9.0, 9.0]), 0.01)
    assert speed[0] == INF
    assert speed[1] == brake_speed(np.array([0.3]), np.array([9.0]),
                                   0.01)[0]


def test_the_robot_side_follows_a_continuous_joint_as_a_limited_one(arm):
    """follow_arm_command with the arm's own limits (Limits.of_robot:
    -inf and inf on the continuous joints) many turns from home: the
    same commands, bit for bit, as with limits 1e3 rad away, while a
    target runs off too fast (held to the speed and acceleration
    limits); never NaN."""
    limits = Limits.of_robot(HardwareOptions(), arm)
    free = _free()
    np.testing.assert_array_equal(limits.upper[free], INF)
    far = limits._replace(lower=np.where(free, -1e3, limits.lower),
                          upper=np.where(free, 1e3, limits.upper))
    period = HardwareOptions().publish_period
    start = np.array(HOMES[7]) + np.where(free, 6.0 * np.pi, 0.0)
    states = {id(limits): (start.copy(), np.zeros(7)),
              id(far): (start.copy(), np.zeros(7))}
    for k in range(200):
        target = start + np.where(free, 3.0, 0.5) * period * (k + 1)
        commands = []
        for given in (limits, far):
            last, velocity = states[id(given)]
            command, velocity, _ = follow_arm_command(
                target, np.full(7, 3.0), last, velocity, period, given)
            states[id(given)] = (command, velocity)
            commands.append(command)
        np.testing.assert_array_equal(commands[0], commands[1])
        assert np.all(np.isfinite(commands[0]))
    last, velocity = states[id(limits)]
    assert np.all(np.abs(velocity) <= limits.joint_speed * (1 + 1e-9))


def test_sampling_a_continuous_joint_takes_one_turn(arm):
    """The tuning's survey and the bench's problems draw a continuous
    joint's angle from one turn (numpy refused the infinite range); a
    limited joint's range is its own."""
    lower, upper = configuration_range(arm.lower, arm.upper)
    free = _free()
    np.testing.assert_array_equal(lower[free], ONE_TURN[0])
    np.testing.assert_array_equal(upper[free], ONE_TURN[1])
    np.testing.assert_array_equal(lower[~free], arm.lower[~free])
    survey = survey_capability(arm, count=20)
    assert np.all(np.isfinite(survey.samples)) and survey.home > 0.0
    problems = make_problems(5, 0, arm)
    for problem in problems:
        q = problem.arm_position
        assert np.all(np.abs(q[free]) <= 0.8 * np.pi)
        assert np.all(np.abs(q[~free]) <= 0.8 * 2.5)


def test_the_arm_servo_refuses_an_infinite_command_as_a_position():
    """On a continuous joint any finite angle is within its position
    limits, and an infinite one beyond them, as on a limited joint (it
    was taken as within and reported as a speed of inf)."""
    lower, upper = np.array([-INF, -2.5]), np.array([INF, 2.5])
    args = (np.zeros(2), np.zeros(2), 0.01, lower, upper, np.full(2, 2.0),
            np.full(2, 9.0))
    assert arm_command_violation(np.array([1e4, 0.0]), np.array([1e4, 0.0]),
                                 *args[1:]) is None
    for value in (INF, -INF):
        violation = arm_command_violation(np.array([value, 0.0]), *args)
        assert (violation.joint, violation.kind, violation.value,
                violation.limit) == (0, "position", value, value)


def test_the_stages_linearise_on_a_continuous_joint_arm(arm):
    """The arm controller's and the capability's stages of that arm in
    AutoDiffXd, by Drake's Linearize: at rest the controller's A and B
    finite (B maps a twist to rates), and the
    capability's D is dC_m/dq = P_jnt dm/dq + m dP_jnt/dq of the float
    functions."""
    q = np.array(HOMES[7])
    # Without the self-motion, which drifts (no equilibrium).
    system = ArmCartesianVelocityController(
        ArmControllerParameters(self_motion_gain=0.0), kinematics=arm)
    context = system.CreateDefaultContext()
    system.set_arm_position(context, q)
    system.get_input_port(0).FixValue(context, np.zeros(6))
    linear = Linearize(system, context)
    assert np.all(np.isfinite(linear.A())) and np.all(np.isfinite(
        linear.B()))
    assert np.abs(linear.B()).max() > 0.0
    stage = ArmCapability(arm=arm)
    context = stage.CreateDefaultContext()
    stage.get_input_port(0).FixValue(context, q)
    linear = Linearize(stage, context, output_port_index=stage.GetOutputPort(
        "capability").get_index())
    k_j = arm.model.description.tuning.joint_limit_gain
    expected = capability.capability_joint_gradient(
        arm.evaluate(q).J_a, q, arm.lower, arm.upper, k_j)
    np.testing.assert_allclose(linear.D()[0], expected, rtol=1e-5,
                               atol=1e-9)
