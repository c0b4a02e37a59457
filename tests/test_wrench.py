"""The external wrench on the tool (drake_wbc.math.wrench) and its stage,
ExternalWrenchEstimator, against the formula as written with both poses
from the plant, the tool's weight alone, and bad measurements."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue
from pydrake.math import RollPitchYaw, RotationMatrix

from drake_wbc.math.wrench import (
    STANDARD_GRAVITY,
    ToolPayload,
    external_wrench,
    tool_motion,
)
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics, ArmMount
from drake_wbc.stages.wrench import ExternalWrenchEstimator, tool_weight_reading


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


@pytest.fixture(scope="module")
def estimator(arm):
    return ExternalWrenchEstimator(arm)


def wrench_as_written(reading, X_AM, X_AT, mass, p_com):
    """F_ext with np.cross and both poses: the weight removed in M, then
    the wrench moved to T and expressed in T_a."""
    R = X_AM.rotation().matrix()
    weight = R.T @ [0.0, 0.0, -mass * STANDARD_GRAVITY]
    f = R @ (reading[:3] - weight)
    tau = R @ (reading[3:] - np.cross(p_com, weight)) + np.cross(
        X_AM.translation() - X_AT.translation(), f)
    return np.r_[f, tau]


def random_configurations(arm, count, seed):
    rng = np.random.default_rng(seed)
    return [rng.uniform(arm.lower, arm.upper) for _ in range(count)]


def test_external_wrench_is_the_formula_as_written(arm):
    rng = np.random.default_rng(14)
    model = arm.model
    for q in random_configurations(arm, 5, 15):
        X_AM = arm.frame_pose(q, model.ft_measurement_frame)
        X_AT = arm.frame_pose(q, model.tcp_frame)
        reading, p_com, mass = rng.normal(size=6), rng.normal(size=3), 1.3
        R = X_AM.rotation().matrix()
        payload = ToolPayload(mass, p_com, R.T @ (X_AM.translation()
                                                  - X_AT.translation()))
        np.testing.assert_allclose(
            external_wrench(reading, R, payload),
            wrench_as_written(reading, X_AM, X_AT, mass, p_com),
            rtol=0, atol=1e-13)


def test_the_estimate_uses_both_poses_of_the_plant(arm, estimator):
    """Random configurations and readings, and the tool's own weight
    (F_ext = 0): the stage against the formula with both poses from the
    plant."""
    rng = np.random.default_rng(8)
    context = estimator.CreateDefaultContext()
    model = arm.model
    mass, p_com = estimator._tool_mass, estimator._p_M_com
    for trial in range(20):
        q = rng.uniform(arm.lower, arm.upper)
        reading = (tool_weight_reading(arm, q) if trial % 5 == 0
                   else 10.0 ** rng.uniform(-2, 3) * rng.normal(size=6))
        estimator.GetInputPort("arm_position").FixValue(context, q)
        estimator.GetInputPort("wrist_wrench").FixValue(context, reading)
        actual = estimator.GetOutputPort("external_wrench").Eval(context)
        size = 10.0 * mass * STANDARD_GRAVITY + np.abs(reading).max()
        np.testing.assert_allclose(actual, wrench_as_written(
            reading, arm.frame_pose(q, model.ft_measurement_frame),
            arm.frame_pose(q, model.tcp_frame), mass, p_com),
            rtol=0, atol=1e-12 * size)
        if trial % 5 == 0:
            np.testing.assert_allclose(actual, 0.0, atol=1e-12 * size)


def test_the_weight_alone_is_removed_at_home(arm, estimator):
    context = estimator.CreateDefaultContext()
    q = np.array(HOME_ARM_POSITIONS, dtype=float)
    estimator.GetInputPort("arm_position").FixValue(context, q)
    weight = tool_weight_reading(arm, q)
    np.testing.assert_allclose(np.linalg.norm(weight[:3]),
                               estimator._tool_mass * STANDARD_GRAVITY)
    estimator.GetInputPort("wrist_wrench").FixValue(context, weight)
    np.testing.assert_array_equal(estimator.GetOutputPort("external_wrench").Eval(context),
                                  np.zeros(6))


@pytest.mark.parametrize("compensate", [False, True],
                         ids=["weight", "inertia"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_bad_measurements(arm, estimator, compensate, bad):
    """A non-finite reading makes the wrench non-finite (the checks
    downstream see it); a non-finite joint angle makes every entry NaN,
    in both frames, in double and AutoDiffXd, and for the lever from the
    plant: nothing raises in a tick."""
    from drake_wbc.math.wrench import WrenchEstimatorParameters

    if compensate:
        estimator = ExternalWrenchEstimator(arm, WrenchEstimatorParameters(
            inertia_compensation=True))
    q = np.array(HOME_ARM_POSITIONS, dtype=float)
    reading = np.ones(6)
    reading[2] = bad
    for system in (estimator, estimator.ToAutoDiffXd()):
        context = system.CreateDefaultContext()
        system.GetInputPort("arm_position").FixValue(context, q)
        system.GetInputPort("wrist_wrench").FixValue(context, reading)
        assert not np.all(np.isfinite(ExtractValue(
            system.GetOutputPort("external_wrench").Eval(context))))
    for system in (estimator, estimator.ToAutoDiffXd()):
        context = system.CreateDefaultContext()
        bad_q = q.copy()
        bad_q[1] = bad
        if compensate:  # the reading's time: the remembered positions
            context.SetDiscreteState(np.tile(bad_q, 3))
        system.GetInputPort("arm_position").FixValue(context, bad_q)
        system.GetInputPort("wrist_wrench").FixValue(context, np.ones(6))
        for port in ("external_wrench", "external_wrench_in_base"):
            assert np.isnan(ExtractValue(
                system.GetOutputPort(port).Eval(context))).all(), port
    assert np.isnan(estimator._estimate(np.r_[bad_q, np.ones(6)])).all()


def test_autodiff_values_and_the_readings_derivative(arm, estimator):
    """In AutoDiffXd the same values, and the derivative w.r.t. the
    reading is the constant map diag(R_AM, R_AM) [[I, 0], [S(p_TM), I]]
    (central differences of a linear function: exact to round-off)."""
    converted = estimator.ToAutoDiffXd()
    rng = np.random.default_rng(3)
    q = rng.uniform(arm.lower, arm.upper)
    reading = rng.normal(size=6)
    context = estimator.CreateDefaultContext()
    estimator.GetInputPort("arm_position").FixValue(context, q)
    estimator.GetInputPort("wrist_wrench").FixValue(context, reading)
    ad_context = converted.CreateDefaultContext()
    converted.GetInputPort("arm_position").FixValue(ad_context, q)
    converted.GetInputPort("wrist_wrench").FixValue(ad_context, np.array(
        [AutoDiffXd(r, e) for r, e in zip(reading, np.eye(6), strict=True)],
        dtype=object))
    value = converted.GetOutputPort("external_wrench").Eval(ad_context)
    np.testing.assert_allclose(ExtractValue(value).ravel(),
                               estimator.GetOutputPort("external_wrench").Eval(context),
                               rtol=0, atol=1e-12)
    R = arm.frame_pose(q, arm.model.ft_measurement_frame).rotation().matrix()
    p_TM = estimator._payload.sensor_from_tcp
    S = np.array([[0.0, -p_TM[2], p_TM[1]], [p_TM[2], 0.0, -p_TM[0]],
                  [-p_TM[1], p_TM[0], 0.0]])
    expected = np.block([[R, np.zeros((3, 3))], [R @ S, R]])
    np.testing.assert_allclose(ExtractGradient(value), expected, atol=1e-8)


def test_the_lever_from_the_plant_is_the_welded_one(arm, estimator):
    """The estimate of a tool not welded to the sensor (the lever from the
    plant each tick) gives, on our welded tool, the stage's wrench."""
    rng = np.random.default_rng(4)
    context = estimator.CreateDefaultContext()
    for q in random_configurations(arm, 5, 16):
        reading = 10.0 * rng.normal(size=6)
        estimator.GetInputPort("arm_position").FixValue(context, q)
        estimator.GetInputPort("wrist_wrench").FixValue(context, reading)
        np.testing.assert_allclose(
            estimator._estimate(np.r_[q, reading]),
            estimator.GetOutputPort("external_wrench").Eval(context),
            rtol=0, atol=1e-12)


def test_the_lever_asks_the_plant_for_each_pose_once(arm, estimator,
                                                      monkeypatch):
    asked = []
    frame_pose = arm.frame_pose

    def counted(q_a, frame):
        asked.append(frame.name())
        return frame_pose(q_a, frame)

    monkeypatch.setattr(arm, "frame_pose", counted)
    estimator._estimate(np.r_[arm.home, np.zeros(6)])
    assert sorted(asked) == sorted(
        {arm.model.ft_measurement_frame.name(), arm.model.tcp_frame.name()})


MOUNTS = {"turned": ArmMount(yaw=0.5 * np.pi),
          "tilted": ArmMount(yaw=-0.4, tilt=0.35)}


@pytest.mark.parametrize("mount", MOUNTS.values(), ids=MOUNTS.keys())
def test_a_mounted_arm_gives_the_wrench_in_each_dmps_frame(mount):
    """An arm mounted turned or tilted on the base: the sensor's reading
    made from the world's gravity and a known force and torque at the tool
    centre point (the tool in static equilibrium, poses of the mounted
    plant with T_b at the world's origin), and the estimate gives back
    that wrench in T_b (external_wrench_in_base) and in T_a
    (external_wrench, R_ba^T of it)."""
    arm = ArmKinematics(mount=mount)
    estimator = ExternalWrenchEstimator(arm)
    context = estimator.CreateDefaultContext()
    plant, model = arm.plant, arm.model
    plant_context = plant.CreateDefaultContext()
    tool = plant.GetBodyByName("wiping_tool", model.tool)
    mass = tool.get_mass(plant_context)
    np.testing.assert_allclose(arm.R_ba, mount.rotation(), atol=1e-15)
    rng = np.random.default_rng(21)
    for q in random_configurations(arm, 6, 22):
        plant.SetPositions(plant_context, model.arm, q)
        X_WM = model.ft_measurement_frame.CalcPoseInWorld(plant_context)
        X_WT = model.tcp_frame.CalcPoseInWorld(plant_context)
        p_W_com = tool.CalcCenterOfMassInBodyFrame(plant_context)
        p_W_com = tool.body_frame().CalcPoseInWorld(plant_context).multiply(
            p_W_com)
        force, torque = 20.0 * rng.normal(size=3), 2.0 * rng.normal(size=3)
        weight = np.array([0.0, 0.0, -mass * STANDARD_GRAVITY])
        p_M = X_WM.translation()
        # What the tool exerts on the sensor: all that acts on the tool,
        # about M, in M.
        on_sensor = np.r_[force + weight, torque + np.cross(
            X_WT.translation() - p_M, force) + np.cross(p_W_com - p_M,
                                                        weight)]
        R_WM = X_WM.rotation().matrix()
        reading = np.r_[R_WM.T @ on_sensor[:3], R_WM.T @ on_sensor[3:]]
        estimator.GetInputPort("arm_position").FixValue(context, q)
        estimator.GetInputPort("wrist_wrench").FixValue(context, reading)
        size = 10.0 * (mass * STANDARD_GRAVITY + np.abs(reading).max())
        expected = np.r_[force, torque]  # T_b is the world here
        np.testing.assert_allclose(
            estimator.GetOutputPort("external_wrench_in_base").Eval(context),
            expected, rtol=0, atol=1e-12 * size)
        R_ab = arm.R_ba.T
        np.testing.assert_allclose(
            estimator.GetOutputPort("external_wrench").Eval(context),
            np.r_[R_ab @ force, R_ab @ torque], rtol=0, atol=1e-12 * size)
        # The tool's weight alone (tool_weight_reading) is no wrench.
        estimator.GetInputPort("wrist_wrench").FixValue(
            context, tool_weight_reading(arm, q))
        np.testing.assert_allclose(
            estimator.GetOutputPort("external_wrench_in_base").Eval(context),
            0.0, atol=1e-12 * size)


def test_an_arm_turned_in_its_own_model_gives_the_wrench_in_t_b(tmp_path):
    """A robot whose own model directives weld the arm turned and tilted
    on the base (no ArmMount: ^bR_a from the model, not the identity):
    the estimate is the one of the same arm mounted so by an ArmMount,
    F_ext in T_b and R_ba^T of it in T_a."""
    from drake_wbc.robot.description import (
        load_robot_description,
        models_dir,
    )
    from drake_wbc.robot.model import make_robot_plant

    mount = ArmMount(yaw=0.5 * np.pi, tilt=0.3)
    rpy = RollPitchYaw(RotationMatrix(mount.rotation())).vector()
    directives = (models_dir() / "mcr.dmd.yaml").read_text().replace(
        "child: elfin5::base_link\n",
        "child: elfin5::base_link\n    X_PC:\n      rotation: !Rpy\n"
        f"        deg: {np.degrees(rpy).tolist()}\n", 1)
    (tmp_path / "turned.dmd.yaml").write_text(directives)
    text = (models_dir() / "mcr.robot.yaml").read_text().replace(
        "package://drake_wbc/mcr.dmd.yaml", "turned.dmd.yaml")
    (tmp_path / "turned.robot.yaml").write_text(text.replace(
        "  packages:\n    drake_wbc: .\n", ""))
    turned = ArmKinematics(*make_robot_plant(
        load_robot_description(tmp_path / "turned.robot.yaml")))
    mounted = ArmKinematics(mount=mount)
    np.testing.assert_allclose(turned.R_ba, mounted.R_ba, atol=1e-12)
    estimates = [ExternalWrenchEstimator(a) for a in (turned, mounted)]
    contexts = [e.CreateDefaultContext() for e in estimates]
    rng = np.random.default_rng(25)
    for q in random_configurations(mounted, 3, 26):
        reading = 10.0 * rng.normal(size=6)
        for estimator, context in zip(estimates, contexts, strict=True):
            estimator.GetInputPort("arm_position").FixValue(context, q)
            estimator.GetInputPort("wrist_wrench").FixValue(context, reading)
        for port in ("external_wrench_in_base", "external_wrench"):
            np.testing.assert_allclose(
                *(e.GetOutputPort(port).Eval(c)
                  for e, c in zip(estimates, contexts, strict=True)),
                atol=1e-9, err_msg=port)


def test_the_shipped_robot_has_one_wrench_in_both_frames(arm, estimator):
    """R_ba = I: the two outputs are the same vector, to the bit."""
    context = estimator.CreateDefaultContext()
    rng = np.random.default_rng(23)
    for q in random_configurations(arm, 3, 24):
        estimator.GetInputPort("arm_position").FixValue(context, q)
        estimator.GetInputPort("wrist_wrench").FixValue(
            context, rng.normal(size=6))
        np.testing.assert_array_equal(
            estimator.GetOutputPort("external_wrench").Eval(context),
            estimator.GetOutputPort("external_wrench_in_base").Eval(context))


def test_tool_motion_of_a_known_motion():
    """Central differences of a tool whose centre moves on a parabola and
    which turns about a fixed axis at a steady angular acceleration: a
    exactly, w_dot and w to the small-angle bound, dH = I w_dot + w x I w
    of the inertia turned into L."""
    rng = np.random.default_rng(31)
    h = 0.01
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    S = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    inertia = np.diag([0.002, 0.003, 0.001])
    payload = ToolPayload(0.4, np.zeros(3), np.zeros(3), inertia=inertia)
    p0, v, a = rng.normal(size=(3, 3))
    w0, w_dot = 1.2, 30.0
    times = np.array([-h, 0.0, h])
    rotations = [np.eye(3) + np.sin(th) * S + (1 - np.cos(th)) * S @ S
                 for th in w0 * times + 0.5 * w_dot * times**2]
    positions = [p0 + v * t + 0.5 * a * t * t for t in times]
    motion = tool_motion(np.array(rotations), np.array(positions), payload,
                         h)
    np.testing.assert_allclose(motion[:3], a, rtol=1e-9, atol=1e-9)
    I_L = rotations[1] @ inertia @ rotations[1].T
    expected = I_L @ (w_dot * axis) + np.cross(w0 * axis, I_L @ (w0 * axis))
    np.testing.assert_allclose(motion[3:], expected, rtol=2e-3, atol=1e-6)


@pytest.mark.parametrize("mount", [ArmMount(), MOUNTS["tilted"]],
                         ids=["shipped", "tilted"])
def test_the_inertial_reaction_is_removed_as_drake_computes_it(mount):
    """The arm on a quadratic joint path (q = q0 + v t + a t^2 / 2): the
    reading that the tool's Newton-Euler equations give with Drake's
    spatial inertia and spatial acceleration of the tool (gravity, a
    known external wrench at the TCP, the tool's inertial reaction), read
    at the middle of three ticks with the joints of the last (sensor_delay
    1), gives the external wrench back in T_b to the central differences'
    O(h^2); without the compensation the reaction stays in it."""
    from pydrake.multibody.math import SpatialForce

    from drake_wbc.math.wrench import WrenchEstimatorParameters

    h = 0.01
    arm = ArmKinematics(mount=mount)
    plant, model = arm.plant, arm.model
    tool = plant.GetBodyByName("wiping_tool", model.tool)
    context = plant.CreateDefaultContext()
    rng = np.random.default_rng(32)
    q0 = HOME_ARM_POSITIONS + rng.uniform(-0.3, 0.3, 6)
    v, a = rng.uniform(-1.0, 1.0, 6), rng.uniform(-20.0, 20.0, 6)
    q_of = [q0 + v * t + 0.5 * a * t * t for t in (-h, 0.0, h)]
    # At the middle sample: the tool's motion from Drake.
    plant.SetPositions(context, model.arm, q_of[1])
    plant.SetVelocities(context, model.arm, v)
    vdot = np.zeros(plant.num_velocities())
    vdot[[plant.GetJointByName(f"joint{i}", model.arm).velocity_start()
          for i in range(1, 7)]] = a
    A = plant.CalcSpatialAccelerationsFromVdot(context, vdot)[
        int(tool.index())]
    X_WB = tool.body_frame().CalcPoseInWorld(context)
    V_WB = tool.body_frame().CalcSpatialVelocityInWorld(context)
    M_B = tool.CalcSpatialInertiaInBodyFrame(context).ReExpress(
        X_WB.rotation())
    # Newton-Euler about the tool's centre of mass, in W.
    p_com = M_B.get_com()
    w = V_WB.rotational()
    m = M_B.get_mass()
    a_com = A.translational() + np.cross(A.rotational(), p_com) + np.cross(
        w, np.cross(w, p_com))
    I_com = M_B.Shift(p_com).CalcRotationalInertia().CopyToFullMatrix3()
    inertial_torque_com = I_com @ A.rotational() + np.cross(w, I_com @ w)
    p_Wcom = X_WB.translation() + p_com
    X_WM = model.ft_measurement_frame.CalcPoseInWorld(context)
    X_WT = model.tcp_frame.CalcPoseInWorld(context)
    p_M = X_WM.translation()
    push = SpatialForce(tau=[0.2, -0.1, 0.3], f=[3.0, -2.0, 4.0])
    f_ext, tau_ext_T = push.translational(), push.rotational()
    weight = np.array([0.0, 0.0, -m * STANDARD_GRAVITY])
    # What the tool exerts on the sensor, about M: all that acts on the
    # tool but the sensor, less its rate of momentum.
    force = f_ext + weight - m * a_com
    torque = (tau_ext_T + np.cross(X_WT.translation() - p_M, f_ext)
              + np.cross(p_Wcom - p_M, weight - m * a_com)
              - inertial_torque_com)
    R_WM = X_WM.rotation().matrix()
    reading = np.r_[R_WM.T @ force, R_WM.T @ torque]
    expected = np.r_[f_ext, tau_ext_T]
    for compensate in (True, False):
        estimator = ExternalWrenchEstimator(arm, WrenchEstimatorParameters(
            inertia_compensation=compensate), time_step=h)
        ctx = estimator.CreateDefaultContext()
        estimator.GetInputPort("wrist_wrench").FixValue(ctx, reading)
        if compensate:
            ctx.SetDiscreteState(np.r_[q_of[1], q_of[0], q_of[0]])
            estimator.GetInputPort("arm_position").FixValue(ctx, q_of[2])
        else:
            estimator.GetInputPort("arm_position").FixValue(ctx, q_of[1])
        estimate = estimator.GetOutputPort(
            "external_wrench_in_base").Eval(ctx)
        error = np.abs(estimate - expected)
        if compensate:
            assert np.max(error[:3]) < 0.01 * m * np.linalg.norm(a_com)
            assert np.max(error[3:]) < 0.002
        else:
            np.testing.assert_allclose(estimate[:3] - expected[:3],
                                       -m * a_com, rtol=1e-9, atol=1e-9)


def test_the_compensating_estimator_in_autodiff_and_its_checks(arm):
    """In AutoDiffXd the same values (the tool's motion through the
    float kinematics); bad parameters are refused naming the field."""
    from drake_wbc.math.wrench import WrenchEstimatorParameters

    params = WrenchEstimatorParameters(inertia_compensation=True)
    estimator = ExternalWrenchEstimator(arm, params)
    converted = estimator.ToAutoDiffXd()
    rng = np.random.default_rng(33)
    q = HOME_ARM_POSITIONS + rng.uniform(-0.2, 0.2, 6)
    past = np.r_[q - 0.001, q - 0.003, q - 0.004]
    reading = rng.normal(size=6)
    values = []
    for system in (estimator, converted):
        context = system.CreateDefaultContext()
        context.SetDiscreteState(past)
        system.GetInputPort("arm_position").FixValue(context, q)
        system.GetInputPort("wrist_wrench").FixValue(context, reading)
        values.append(ExtractValue(system.GetOutputPort(
            "external_wrench").Eval(context)).ravel())
    np.testing.assert_allclose(values[1], values[0], rtol=0, atol=1e-12)
    for name, value in (("sensor_delay", 3), ("sensor_delay", 0),
                        ("inertia_compensation", 1)):
        with pytest.raises(ValueError, match=name):
            WrenchEstimatorParameters(**{name: value})


def test_the_compensating_estimator_remembers_the_last_three_positions(arm):
    """Its periodic update shifts [q(k-1); q(k-2); q(k-3)] to [q(k);
    q(k-1); q(k-2)], the oldest dropped."""
    from drake_wbc.math.wrench import WrenchEstimatorParameters

    estimator = ExternalWrenchEstimator(arm, WrenchEstimatorParameters(
        inertia_compensation=True))
    context = estimator.CreateDefaultContext()
    q = [HOME_ARM_POSITIONS + 0.01 * k for k in range(4)]
    context.SetDiscreteState(np.r_[q[2], q[1], q[0]])
    estimator.GetInputPort("arm_position").FixValue(context, q[3])
    estimator.GetInputPort("wrist_wrench").FixValue(context, np.zeros(6))
    state = estimator.EvalUniquePeriodicDiscreteUpdate(context)
    np.testing.assert_array_equal(state.get_vector().CopyToVector(),
                                  np.r_[q[3], q[2], q[1]])


@pytest.mark.parametrize("mount", [ArmMount(), MOUNTS["tilted"]],
                         ids=["shipped", "tilted"])
def test_the_arm_frame_wrench_follows_a_change_of_the_remembered_positions(
        mount):
    """With inertia compensation both outputs depend on the remembered
    arm positions (the state): after only the state changes, the T_a
    wrench evaluated in the same context is a fresh context's, R_ba^T of
    the T_b one, and not the value before the change."""
    from drake_wbc.math.wrench import WrenchEstimatorParameters

    arm = ArmKinematics(mount=mount)
    estimator = ExternalWrenchEstimator(arm, WrenchEstimatorParameters(
        inertia_compensation=True))
    q = np.asarray(arm.home, dtype=float)
    past = np.r_[q + 0.05, q + 0.1, q + 0.15]
    reading = tool_weight_reading(arm, q)

    def context_with(state):
        context = estimator.CreateDefaultContext()
        context.SetDiscreteState(state)
        estimator.GetInputPort("wrist_wrench").FixValue(context, reading)
        estimator.GetInputPort("arm_position").FixValue(context, q)
        return context

    in_arm = estimator.GetOutputPort("external_wrench")
    in_base = estimator.GetOutputPort("external_wrench_in_base")
    context = context_with(np.tile(q, 3))
    before = in_arm.Eval(context).copy()
    context.SetDiscreteState(past)
    after = in_arm.Eval(context)
    fresh = in_arm.Eval(context_with(past))
    assert np.max(np.abs(fresh - before)) > 1e-3
    np.testing.assert_array_equal(after, fresh)
    R_ab = arm.R_ba.T
    base = in_base.Eval(context)
    np.testing.assert_allclose(after, np.r_[R_ab @ base[:3], R_ab @ base[3:]],
                               rtol=0, atol=1e-12 * np.abs(base).max())


def test_the_arm_must_be_an_arm_kinematics():
    """Anything else than an ArmKinematics (or None) is refused naming
    the argument, as the sibling stages do: a RobotDescription too."""
    from drake_wbc.robot.description import shipped_robot

    for arm in (shipped_robot(), "arm", 6):
        with pytest.raises(ValueError, match=r"arm = .* ArmKinematics"):
            ExternalWrenchEstimator(arm)
    assert isinstance(ExternalWrenchEstimator()._arm, ArmKinematics)
