"""The coupled-DMP stages against the paper's equations, through their ports,
and Drake's linearisation of them against eqs. (lp-admit) and (tf-admit)."""

from functools import partial

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Linearize, VectorLogSink
from shipped_names import FOOTPRINT

from drake_wbc.analysis.frequency import linear_system_response
from drake_wbc.math import cdmp, repulsion
from drake_wbc.math.dmp import DmpParameters
from drake_wbc.stages.cdmp_base import AffineDynamics
from drake_wbc.stages.cdmp_stages import ArmCdmp, BaseCdmp
from drake_wbc.stages.whole_body_cdmp import WholeBodyCdmp

OMEGA = 2 * np.pi * np.logspace(-2, 2, 120)

BASE = cdmp.BaseCdmpParameters(repulsion=repulsion.RepulsiveFieldParameters(
    half_sizes=FOOTPRINT))
"""The base CDMP's parameters on the shipped base's footprint."""


def fix_inputs(system, context, values):
    for name, value in values.items():
        port = system.GetInputPort(name)
        if name == "obstacle_points":
            port.FixValue(context, AbstractValue.Make(np.asarray(value)))
        else:
            port.FixValue(context, np.atleast_1d(value))


def rk4_hold(derivative, x, h, steps=400):
    """Integrates x_dot = derivative(x) over h with fine RK4 steps."""
    dt = h / steps
    for _ in range(steps):
        k1 = derivative(x)
        k2 = derivative(x + dt / 2 * k1)
        k3 = derivative(x + dt / 2 * k2)
        k4 = derivative(x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def rotation_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_affine_dynamics_rejects_a_nonlinear_function():
    with pytest.raises(ValueError, match="affine"):
        AffineDynamics(lambda x, u: x * x + u, 2, 2, 0.0)


@pytest.mark.parametrize("switch", [0, 1])
def test_whole_body_cdmp_matches_its_equation(switch):
    rng = np.random.default_rng(1)
    params = cdmp.WholeBodyCdmpParameters()
    system = WholeBodyCdmp(params, time_step=0.0)
    context = system.CreateDefaultContext()
    x = rng.normal(size=24)
    context.SetContinuousState(x)
    yaw = 0.7
    V_ref, F_b, dV_b = rng.normal(size=(3, 6))
    fix_inputs(system, context, dict(
        reference_velocity=V_ref, wrench=F_b, end_effector_deviation=dV_b,
        base_yaw=yaw, phri_switch=switch))
    R_wb = rotation_z(yaw)

    def to_world(twist):
        return np.concatenate([R_wb @ twist[:3], R_wb @ twist[3:]])

    y, z, C, E = np.split(x, 4)
    expected = cdmp.whole_body_cdmp_derivative(
        y, z, C, E, np.zeros(6), V_ref, to_world(F_b), to_world(dV_b),
        params, S_hri=switch)
    derivatives = system.EvalTimeDerivatives(context).CopyToVector()
    np.testing.assert_allclose(derivatives, np.concatenate(expected),
                               atol=1e-12)
    y_dot = expected[0]
    output = system.GetOutputPort("end_effector_velocity").Eval(context)
    R_bw = R_wb.T
    np.testing.assert_allclose(
        output, np.concatenate([R_bw @ y_dot[:3], R_bw @ y_dot[3:]]),
        atol=1e-12)


def test_deviation_closes_no_algebraic_loop():
    system = WholeBodyCdmp()
    deviation = system.GetInputPort("end_effector_deviation").get_index()
    assert not system.HasDirectFeedthrough(deviation, 0)
    reference = system.GetInputPort("reference_velocity").get_index()
    assert system.HasDirectFeedthrough(reference, 0)


def test_discrete_update_is_the_exact_hold():
    """One discrete update equals a fine integration of the paper's
    equation with the inputs held over the period."""
    rng = np.random.default_rng(2)
    params = cdmp.ArmCdmpParameters()
    system = ArmCdmp(params, time_step=0.01)
    context = system.CreateDefaultContext()
    x = 0.1 * rng.normal(size=18)
    context.SetDiscreteState(x)
    V_a, F = rng.normal(size=(2, 6))
    fix_inputs(system, context, dict(arm_velocity=V_a, wrench=F))

    def derivative(state):
        y, z, C_a = np.split(state, 3)
        return np.concatenate(cdmp.arm_cdmp_derivative(
            y, z, C_a, np.zeros(6), V_a, F, params))

    update = system.EvalUniquePeriodicDiscreteUpdate(context)
    np.testing.assert_allclose(update.get_vector().CopyToVector(),
                               rk4_hold(derivative, x, 0.01), atol=1e-11)


def test_base_cdmp_avoids_and_returns():
    """An obstacle 0.2 m ahead of the footprint pushes the base back; once
    it is gone the base returns onto its commanded path."""
    params = cdmp.BaseCdmpParameters(
        repulsion=repulsion.RepulsiveFieldParameters(half_sizes=FOOTPRINT,
                                                     k_obs=1.0))
    system = BaseCdmp(params)
    context = system.CreateDefaultContext()
    fix_inputs(system, context, dict(base_velocity=[0.1, 0.0, 0.0],
                                     obstacle_points=[[0.6, 0.0]]))
    force = system.repulsive_force(context)
    expected = repulsion.repulsive_force(np.array([[0.6, 0.0]]),
                                    params.repulsion)
    np.testing.assert_allclose(force[:2], expected)
    assert force[0] < 0 and force[2] == 0

    simulator = Simulator(system, context)

    def deviation():
        """y - C: the base's displacement off its commanded path."""
        y, _, C = np.split(context.get_discrete_state_vector().
                           CopyToVector(), 3)
        return y - C

    simulator.AdvanceTo(1.0)
    assert deviation()[0] < -1e-3  # pushed back from the commanded path
    assert deviation()[1] == deviation()[2] == 0.0
    fix_inputs(system, context, dict(obstacle_points=np.zeros((0, 2))))
    simulator.AdvanceTo(5.0)
    np.testing.assert_allclose(deviation(), 0.0, atol=1e-6)  # back on it
    output = system.GetOutputPort("avoiding_base_velocity")
    np.testing.assert_allclose(output.Eval(context), [0.1, 0, 0], atol=1e-6)


def test_tracking_error_is_eliminated():
    """eq. (cdmp-wb-error): a deviation of the end effector, integrated,
    is commanded back: the output's excess over the reference integrates
    to minus the deviation."""
    builder = DiagramBuilder()
    system = builder.AddSystem(WholeBodyCdmp())
    log = builder.AddSystem(VectorLogSink(6, publish_period=0.01))
    builder.Connect(system.get_output_port(), log.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = system.GetMyMutableContextFromRoot(
        simulator.get_mutable_context())
    reference = np.array([0.1, 0, 0, 0, 0, 0])
    deviation = np.array([0, 0.02, 0, 0, 0, 0])
    fix_inputs(system, context, dict(reference_velocity=reference,
                                     wrench=np.zeros(6),
                                     end_effector_deviation=deviation))
    simulator.AdvanceTo(0.5)  # 0.5 s at 0.02 m/s: 0.01 m off in y
    fix_inputs(system, context, dict(end_effector_deviation=np.zeros(6)))
    simulator.AdvanceTo(4.0)
    data = log.FindLog(simulator.get_context()).data()
    excess = (data - reference[:, None]).sum(axis=1) * 0.01
    assert excess[1] == pytest.approx(-0.01, abs=2e-4)
    np.testing.assert_allclose(data[:, -1], reference, atol=1e-6)


def lp_admit(k_p, k_d, tau, alpha_z, beta_z, omega):
    """eq. (lp-admit): Y/F of the stiffness-coupled DMP."""
    s = 1j * omega
    return (k_p * (tau**2 + k_d) * s + k_p * tau * alpha_z) / (
        tau**2 * s**2 + tau * alpha_z * s + alpha_z * beta_z)


def lp_admit_zoh(k_p, k_d, tau, alpha_z, h, omega):
    """The exact zero-order-hold equivalent of eq. (lp-admit) with
    beta_z = alpha_z / 4 (a double pole at -a, a = alpha_z / (2 tau)),
    from partial fractions of H(s)/s = N(s) / (s (s + a)^2):
    A/s + B/(s + a) + C/(s + a)^2 with A = N(0)/a^2, B = -A,
    C = -N(-a)/a, so H_d = A + B (z-1)/(z-q) + C h q (z-1)/(z-q)^2."""
    a = alpha_z / (2 * tau)

    def N(s):
        return k_p * ((tau**2 + k_d) * s + tau * alpha_z) / tau**2

    A, C = N(0.0) / a**2, -N(-a) / a
    q = np.exp(-a * h)
    z = np.exp(1j * omega * h)
    return A - A * (z - 1) / (z - q) + C * h * q * (z - 1) / (z - q) ** 2


def linearize_arm(params, time_step, axis):
    system = ArmCdmp(params, time_step=time_step)
    context = system.CreateDefaultContext()
    # An equilibrium: the force axes at F_d, no load on the stiffness axes.
    fix_inputs(system, context, dict(arm_velocity=np.zeros(6),
                                     wrench=params.F_d * (1 - params.S_m)))
    wrench = system.GetInputPort("wrench").get_index()
    linear = Linearize(system, context, input_port_index=wrench)
    position = np.zeros((1, 18))
    position[0, axis] = 1.0  # y of that axis
    return linear_system_response(linear, OMEGA, outputs=position)[:, 0,
                                                                   axis]


@pytest.mark.parametrize("k_d", [0.0, 0.3])
@pytest.mark.parametrize("time_step", [0.0, 0.01])
def test_stiffness_coupled_arm_matches_eq_lp_admit(k_d, time_step):
    params = cdmp.ArmCdmpParameters(S_m=np.ones(6), k_d=k_d)
    dmp = params.dmp
    response = linearize_arm(params, time_step, axis=2)
    if time_step == 0.0:
        expected = lp_admit(params.k_p, k_d, dmp.tau, dmp.alpha_z,
                            dmp.resolved_beta_z, OMEGA)
    else:
        expected = lp_admit_zoh(params.k_p, k_d, dmp.tau, dmp.alpha_z,
                                time_step, OMEGA)
    relative = np.abs(response - expected) / np.abs(expected)
    assert relative.max() < 1e-6


@pytest.mark.parametrize("time_step", [0.0, 0.01])
def test_admittance_coupled_arm_matches_eq_tf_admit(time_step):
    """Along a force-controlled axis (S_m = 0) the arm is the
    admittance-coupled DMP: Y/F = D_a / s with D_a = k_f, whose exact
    zero-order-hold equivalent is k_f h / (z - 1)."""
    params = cdmp.ArmCdmpParameters()
    response = linearize_arm(params, time_step, axis=0)
    if time_step == 0.0:
        expected = params.k_f / (1j * OMEGA)
    else:
        expected = params.k_f * time_step / (np.exp(1j * OMEGA * time_step)
                                             - 1)
    relative = np.abs(response - expected) / np.abs(expected)
    assert relative.max() < 1e-6


def test_phri_switch_turns_the_force_control_off():
    system = ArmCdmp()
    context = system.CreateDefaultContext()
    fix_inputs(system, context, dict(arm_velocity=np.zeros(6),
                                     wrench=np.zeros(6)))
    output = system.get_output_port()
    # Out of contact the force loop drives towards the surface at k_f F_d.
    assert output.Eval(context)[0] == pytest.approx(
        -system.params.k_f * system.params.F_d[0])
    fix_inputs(system, context, dict(phri_switch=1.0))
    assert output.Eval(context)[0] == 0.0
    fix_inputs(system, context, dict(phri_switch=0.0,
                                     desired_wrench=np.zeros(6)))
    assert output.Eval(context)[0] == 0.0


@pytest.mark.parametrize(("stage", "params"), [
    (WholeBodyCdmp, cdmp.WholeBodyCdmpParameters),
    (BaseCdmp, lambda: BASE), (ArmCdmp, cdmp.ArmCdmpParameters)])
def test_scalar_conversion(stage, params):
    system = stage(params(), time_step=0.005)
    converted = system.ToAutoDiffXd()
    assert converted.params is system.params
    assert converted.num_output_ports() == system.num_output_ports()


@pytest.mark.parametrize("autodiff", [False, True])
@pytest.mark.parametrize("s_hri", [0.0, 1.0, None])
def test_arm_cdmp_is_its_reference_body(s_hri, autodiff):
    """ArmCdmp against math.cdmp.arm_cdmp_derivative itself, on random
    states and inputs, for S_hri 0 and 1 (fixed, or the default while
    unconnected, with F_d the parameter's): the output
    is y_dot, the update a fine integration of the equation over the
    period with the inputs held."""
    from pydrake.autodiffutils import ExtractValue

    rng = np.random.default_rng(11)
    params = cdmp.ArmCdmpParameters(S_m=[1, 0, 1, 0, 0, 1], k_d=0.2)
    double = ArmCdmp(params, time_step=0.01,
                     phri_switch=1.0 if s_hri is None else 0.0)
    system = double.ToAutoDiffXd() if autodiff else double
    for _ in range(5):
        context = system.CreateDefaultContext()
        x = rng.normal(size=18)
        context.SetDiscreteState(x)
        V_a, F = rng.normal(size=(2, 6))
        F_d = params.F_d if s_hri is None else 10 * rng.normal(size=6)
        inputs = dict(arm_velocity=V_a, wrench=F)
        if s_hri is not None:
            inputs.update(desired_wrench=F_d, phri_switch=s_hri)
        fix_inputs(system, context, inputs)
        given = cdmp.ArmCdmpParameters(k_p=params.k_p, k_d=params.k_d,
                                       k_f=params.k_f, S_m=params.S_m,
                                       F_d=F_d, dmp=params.dmp)
        switch = 1.0 if s_hri is None else s_hri

        def derivative(state, given=given, switch=switch, V_a=V_a, F=F):
            y, z, C_a = np.split(state, 3)
            return np.concatenate(cdmp.arm_cdmp_derivative(
                y, z, C_a, np.zeros(6), V_a, F, given, S_hri=switch))

        output = ExtractValue(system.get_output_port().Eval(
            context)).astype(float).ravel()
        np.testing.assert_allclose(output, derivative(x)[:6], rtol=1e-12,
                                   atol=1e-12)
        update = ExtractValue(system.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector()).astype(float).ravel()
        np.testing.assert_allclose(update, rk4_hold(derivative, x, 0.01),
                                   atol=1e-10)


def test_bad_time_step_is_rejected():
    with pytest.raises(ValueError, match="time_step"):
        ArmCdmp(time_step=-0.01)


@pytest.mark.parametrize("stage, params", [
    (BaseCdmp, partial(cdmp.BaseCdmpParameters, repulsion=BASE.repulsion)),
    (WholeBodyCdmp, cdmp.WholeBodyCdmpParameters),
    (ArmCdmp, cdmp.ArmCdmpParameters)])
def test_a_stage_built_by_hand_refuses_a_dmp_its_period_cannot_sample(
        stage, params):
    """Each stage checks its DMP against its control period where the two
    meet, as the controller's parameters do: tau = 0.03 puts the fastest
    pole, sqrt(alpha_z beta_z) / tau = 12.5 / 0.03 = 416.7 rad/s, above
    pi / 0.01 = 314.2 rad/s (the stage took it); tau = 0.04 (312.5) is
    below, and continuous time samples every DMP."""
    too_fast = params(dmp=DmpParameters(tau=0.03))
    with pytest.raises(ValueError, match=(
            r"params\.dmp\.alpha_z = 25\.0, beta_z = 6\.25 and tau = 0\.03 s "
            r"are not allowed with time_step = 0\.01 s: .*fastest pole "
            r"\(416\.667 rad/s\) must lie below the Nyquist rate")):
        stage(too_fast, time_step=0.01)
    stage(params(dmp=DmpParameters(tau=0.04)), time_step=0.01)
    stage(too_fast, time_step=0.0)


def test_a_movement_played_faster_than_its_period_samples_is_refused():
    """A learned movement played at tau = 0.03 runs its DMP's fastest pole
    at 416.7 rad/s, above the control period's Nyquist rate: refused,
    naming the movement's DMP and what to change (the stage played it)."""
    fast = cdmp.WholeBodyCdmpParameters(movement=cdmp.MovementReplay(
        file="movements/teach.yaml", tau=0.03))
    with pytest.raises(ValueError, match=(
            r"movement\.dmp\.alpha_z = .* tau = 0\.03 s are not allowed "
            r"with time_step = 0\.01 s: .*Nyquist.*; play the movement "
            r"slower \(a larger movement\.tau\)")):
        WholeBodyCdmp(fast, time_step=0.01)


@pytest.mark.parametrize("stage", [WholeBodyCdmp, ArmCdmp])
def test_a_bad_default_phri_switch_is_rejected(stage):
    with pytest.raises(ValueError, match=r"phri_switch = 0\.5 is not "
                       "allowed: must be 0 or 1"):
        stage(phri_switch=0.5)


@pytest.mark.parametrize("stage", [WholeBodyCdmp, ArmCdmp])
def test_the_default_phri_switch_acts_while_the_port_is_unconnected(stage):
    """The constructor's phri_switch is S_hri while the port is neither
    connected nor fixed: the same update as with the port fixed to it,
    in the stage and in its scalar-converted copy."""
    rng = np.random.default_rng(7)
    x = rng.normal(size=24 if stage is WholeBodyCdmp else 18)
    names = (("reference_velocity", "wrench", "end_effector_deviation")
             if stage is WholeBodyCdmp else ("arm_velocity", "wrench"))
    inputs = {name: rng.normal(size=6) for name in names}
    for s_hri in (0.0, 1.0):
        system = stage(phri_switch=s_hri)
        updates = []
        for given in (system, system.ToAutoDiffXd()):
            context = given.CreateDefaultContext()
            context.SetDiscreteState(x)
            fix_inputs(given, context, inputs)
            updates.append(given.EvalUniquePeriodicDiscreteUpdate(
                context).get_vector().CopyToVector())
        context = system.CreateDefaultContext()
        context.SetDiscreteState(x)
        fix_inputs(system, context, dict(inputs, phri_switch=s_hri))
        fixed = update_of(system, context)
        other = stage(phri_switch=1.0 - s_hri)
        context = other.CreateDefaultContext()
        context.SetDiscreteState(x)
        fix_inputs(other, context, inputs)
        np.testing.assert_array_equal(updates[0], fixed)
        np.testing.assert_allclose(
            [u.value() if hasattr(u, "value") else u for u in updates[1]],
            fixed, rtol=1e-14, atol=1e-14)
        assert np.abs(update_of(other, context) - fixed).max() > 1e-6


def update_of(system, context):
    return system.EvalUniquePeriodicDiscreteUpdate(
        context).get_vector().CopyToVector()


def to_world(yaw, twist):
    R = rotation_z(yaw)
    return np.concatenate([R @ twist[:3], R @ twist[3:]])


@pytest.mark.parametrize("switch", [0, 1, None])
def test_whole_body_cdmp_output_and_update_are_its_model(switch):
    """In discrete time, the output is y_dot of eq. (cdmp-wb) rotated into
    T_b and the update the model's exact hold, with the wrench and the
    deviation rotated into the world (eq. (3))."""
    rng = np.random.default_rng(4)
    system = WholeBodyCdmp(phri_switch=1.0)
    for _ in range(5):
        context = system.CreateDefaultContext()
        scale = 10.0 ** rng.uniform(-3, 3)
        x = scale * rng.normal(size=24)
        context.SetDiscreteState(x)
        V_ref, dV = scale * rng.normal(size=(2, 6))
        F = 100 * scale * rng.normal(size=6)
        yaw = rng.uniform(-4, 4) if switch is not None else 0.0
        inputs = dict(reference_velocity=V_ref, wrench=F,
                      end_effector_deviation=dV)
        if switch is not None:
            inputs.update(base_yaw=yaw, phri_switch=switch)
        fix_inputs(system, context, inputs)
        model = system._models[1 if switch is None else switch]
        u = np.concatenate([V_ref, to_world(yaw, F), to_world(yaw, dV)])
        y_dot = (model.derivative(x, u * np.r_[np.ones(12), np.zeros(6)])
                 [:6])
        size = 100 * scale
        np.testing.assert_allclose(
            system.get_output_port().Eval(context), to_world(-yaw, y_dot),
            rtol=1e-12, atol=1e-12 * size)
        np.testing.assert_allclose(update_of(system, context),
                                   model.next_state(x, u), rtol=1e-12,
                                   atol=1e-12 * size)


def test_the_deviation_reaches_only_the_update():
    system = WholeBodyCdmp()
    context = system.CreateDefaultContext()
    rng = np.random.default_rng(5)
    fix_inputs(system, context, dict(
        reference_velocity=rng.normal(size=6), wrench=rng.normal(size=6),
        end_effector_deviation=rng.normal(size=6), base_yaw=0.3))
    output = system.get_output_port().Eval(context).copy()
    update = update_of(system, context)
    fix_inputs(system, context, dict(end_effector_deviation=rng.normal(
        size=6)))
    np.testing.assert_array_equal(system.get_output_port().Eval(context),
                                  output)
    assert not np.allclose(update_of(system, context), update)


def test_base_cdmp_shares_one_force_and_result_a_tick():
    """The output computes the repulsive force and the shared result once;
    the update finds both up to date (computes neither again); the force
    is the repulsive field's with no yaw part, and a copy."""
    system = BaseCdmp(BASE)
    context = system.CreateDefaultContext()
    fix_inputs(system, context, dict(base_velocity=[0.1, 0.0, 0.0]))
    points = np.array([[0.6, 0.1], [-0.2, 0.5]])
    fix_inputs(system, context, dict(obstacle_points=points))
    entries = (system._force, system._result)
    assert all(entry.is_out_of_date(context) for entry in entries)
    output = system.get_output_port().Eval(context)
    assert not any(entry.is_out_of_date(context) for entry in entries)
    update = update_of(system, context)
    assert not any(entry.is_out_of_date(context) for entry in entries)
    force = system.repulsive_force(context)
    expected = repulsion.repulsive_force(points, system.params.repulsion)
    np.testing.assert_allclose(force, [*expected, 0.0], rtol=1e-14)
    force[:] = np.nan  # a copy: the cached value stays
    assert np.all(np.isfinite(system.repulsive_force(context)))
    model = system._models[0]
    x = np.zeros(9)
    u = np.r_[0.1, 0.0, 0.0, system.repulsive_force(context)]
    np.testing.assert_allclose(output, model.derivative(x, u)[:3],
                               atol=1e-15)
    np.testing.assert_allclose(update, model.next_state(x, u), atol=1e-15)


def test_base_cdmp_without_points_feels_no_force():
    system = BaseCdmp(BASE)
    context = system.CreateDefaultContext()
    fix_inputs(system, context, dict(base_velocity=[0.1, 0.2, 0.3]))
    np.testing.assert_array_equal(system.repulsive_force(context),
                                  np.zeros(3))
    np.testing.assert_allclose(system.get_output_port().Eval(context),
                               [0.1, 0.2, 0.3], rtol=1e-15)


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_inputs_stay_non_finite(value):
    """A non-finite input makes the output and the update non-finite (so
    the checks downstream still see it)."""
    rng = np.random.default_rng(6)
    for make, port, size in ((ArmCdmp, "wrench", 6),
                             (partial(BaseCdmp, BASE), "base_velocity", 3),
                             (WholeBodyCdmp, "wrench", 6),
                             (WholeBodyCdmp, "reference_velocity", 6)):
        system = make()
        context = system.CreateDefaultContext()
        for i in range(system.num_input_ports()):
            name = system.get_input_port(i).get_name()
            if name not in ("obstacle_points", "phri_switch", "base_yaw",
                            "desired_wrench"):
                system.get_input_port(i).FixValue(context,
                                                  rng.normal(size=size))
        bad = rng.normal(size=size)
        bad[size - 1] = value
        system.GetInputPort(port).FixValue(context, bad)
        with np.errstate(invalid="ignore"):
            assert not np.all(np.isfinite(
                system.get_output_port().Eval(context)))
            assert not np.all(np.isfinite(update_of(system, context)))


def autodiff_copy_values(system, rng, time=1.2):
    """(double output, double update, AutoDiffXd output values, AutoDiffXd
    update values) of `system` and its AutoDiffXd copy at random states
    and inputs."""
    from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff

    converted = system.ToAutoDiffXd()
    context = system.CreateDefaultContext()
    context.SetTime(time)
    context.SetDiscreteState(rng.normal(size=context.num_total_states()))
    ad_context = converted.CreateDefaultContext()
    ad_context.SetTime(AutoDiffXd(time))
    ad_context.SetDiscreteState(InitializeAutoDiff(
        context.get_discrete_state_vector().CopyToVector()).ravel())
    for i in range(system.num_input_ports()):
        port = system.get_input_port(i)
        if port.get_name() == "obstacle_points":
            value = AbstractValue.Make(rng.uniform(-1, 1, (30, 2)))
        else:
            value = rng.normal(size=port.size())
        port.FixValue(context, value)
        converted.get_input_port(i).FixValue(ad_context, value)
    return (system.get_output_port().Eval(context),
            update_of(system, context),
            [a.value() for a in converted.get_output_port().Eval(
                ad_context)],
            [a.value() for a in converted.EvalUniquePeriodicDiscreteUpdate(
                ad_context).get_vector().CopyToVector()])


@pytest.mark.parametrize("stage", [ArmCdmp, partial(BaseCdmp, BASE),
                                   WholeBodyCdmp])
def test_autodiff_copies_compute_the_same_values(stage):
    rng = np.random.default_rng(7)
    output, update, ad_output, ad_update = autodiff_copy_values(stage(), rng)
    np.testing.assert_allclose(ad_output, output, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ad_update, update, rtol=1e-12, atol=1e-12)
