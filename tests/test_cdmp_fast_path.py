"""The double fast paths of the CDMP stages and the movement player
against their general paths (the AutoDiffXd code, run here in double)
and against the formulas they replace, on seeded random inputs, edge
cases included."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector

from drake_wbc.math import cdmp, dmp, repulsion
from drake_wbc.math.demonstration import TcpPose
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.cdmp_stages import ArmCdmp, BaseCdmp
from drake_wbc.stages.whole_body_cdmp import MovementTracking, WholeBodyCdmp

RELATIVE = 1e-12
"""Round-off: the largest allowed difference, relative to the scale of
the terms."""

MOVEMENT = cdmp.MovementReplay(file="movements/teach.yaml", start_time=0.5,
                               goal=[1.7, 0.3, 0.7, -2.9], tau=1.3)
"""The committed movement, to a moved goal and slower."""


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


@pytest.fixture(scope="module")
def player_stage():
    return WholeBodyCdmp(cdmp.WholeBodyCdmpParameters(movement=MOVEMENT))


def assert_close(fast, general, scale):
    """fast equals general to round-off of terms of size `scale`."""
    np.testing.assert_allclose(fast, general, rtol=RELATIVE,
                               atol=RELATIVE * max(scale, 1.0))


def general_output(system, context):
    """The output of the general path (the one AutoDiffXd runs)."""
    output = BasicVector(system.get_output_port(0).size())
    system._output(context, output)
    return output.CopyToVector()


def general_update(system, context):
    values = system.AllocateDiscreteVariables()
    system._update(context, values)
    return values.get_vector().CopyToVector()


def fast_output(system, context):
    return system.get_output_port(0).Eval(context)


def fast_update(system, context):
    return system.EvalUniquePeriodicDiscreteUpdate(
        context).get_vector().CopyToVector()


def compare(system, context, scale):
    """The fast output and update against the general ones."""
    assert system._fast
    assert_close(fast_output(system, context),
                 general_output(system, context), scale)
    if system._time_step > 0.0:
        assert_close(fast_update(system, context),
                     general_update(system, context), scale)


def set_state(system, context, x):
    if system._time_step > 0.0:
        context.SetDiscreteState(x)
    else:
        context.SetContinuousState(x)


@pytest.mark.parametrize("time_step", [0.01, 0.0])
def test_arm_cdmp_fast_path(time_step):
    rng = np.random.default_rng(1)
    system = ArmCdmp(time_step=time_step)
    context = system.CreateDefaultContext()
    ports = {name: system.GetInputPort(name) for name in (
        "arm_velocity", "wrench", "desired_wrench", "phri_switch")}
    for trial in range(12):
        scale = 10.0 ** rng.uniform(-3, 3)
        set_state(system, context, scale * rng.normal(size=18))
        ports["arm_velocity"].FixValue(context, scale * rng.normal(size=6))
        ports["wrench"].FixValue(context, 100 * scale * rng.normal(size=6))
        if trial % 3:  # else the parameter's F_d and S_hri
            ports["desired_wrench"].FixValue(context, rng.normal(size=6))
            ports["phri_switch"].FixValue(context, [rng.uniform(0, 1)])
        compare(system, context, 100 * scale)
        if trial % 3 == 0:
            context = system.CreateDefaultContext()


@pytest.mark.parametrize("time_step", [0.01, 0.0])
def test_base_cdmp_fast_path(time_step):
    """Points far, near, on and inside the footprint, none, and so many
    close ones that the force is bounded (max_force)."""
    rng = np.random.default_rng(2)
    system = BaseCdmp(time_step=time_step)
    context = system.CreateDefaultContext()
    points_port = system.GetInputPort("obstacle_points")
    clouds = [np.zeros((0, 2)), rng.uniform(-5, 5, (300, 2)),
              rng.uniform(-0.9, 0.9, (50, 2)), np.array([[0.4, 0.0]]),
              rng.uniform(-0.1, 0.1, (20, 2))]
    for k, points in enumerate(clouds):
        set_state(system, context, rng.normal(size=9))
        system.GetInputPort("base_velocity").FixValue(context,
                                                      rng.normal(size=3))
        points_port.FixValue(context, AbstractValue.Make(points))
        force = repulsion.repulsive_force(points, system.params.repulsion)
        if k == 4:
            assert np.linalg.norm(force) == pytest.approx(
                system.params.repulsion.max_force)
        compare(system, context, 1.0 + np.linalg.norm(force))
    # Unconnected points: no force.
    context = system.CreateDefaultContext()
    system.GetInputPort("base_velocity").FixValue(context, [0.1, 0.2, 0.3])
    compare(system, context, 1.0)


def test_base_cdmp_shares_one_force_and_result_a_tick():
    """The output computes the repulsive force and the shared result once;
    the update finds both up to date (computes neither again)."""
    system = BaseCdmp()
    context = system.CreateDefaultContext()
    system.GetInputPort("base_velocity").FixValue(context, [0.1, 0.0, 0.0])
    points = np.array([[0.6, 0.1], [-0.2, 0.5]])
    system.GetInputPort("obstacle_points").FixValue(
        context, AbstractValue.Make(points))
    entries = (system._force, system._fast_result)
    assert all(entry.is_out_of_date(context) for entry in entries)
    output = fast_output(system, context)
    assert not any(entry.is_out_of_date(context) for entry in entries)
    update = fast_update(system, context)
    assert not any(entry.is_out_of_date(context) for entry in entries)
    assert_close(output, general_output(system, context), 1.0)
    assert_close(update, general_update(system, context), 1.0)


def fix_whole_body(system, context, rng, scale, connect):
    for name in ("reference_velocity", "end_effector_deviation"):
        system.GetInputPort(name).FixValue(context,
                                           scale * rng.normal(size=6))
    system.GetInputPort("wrench").FixValue(context,
                                           100 * scale * rng.normal(size=6))
    if connect:
        system.GetInputPort("base_yaw").FixValue(
            context, [rng.uniform(-4, 4)])
        system.GetInputPort("phri_switch").FixValue(
            context, [rng.uniform(0, 1)])


@pytest.mark.parametrize("time_step", [0.01, 0.0])
def test_whole_body_cdmp_fast_path(time_step):
    rng = np.random.default_rng(3)
    system = WholeBodyCdmp(cdmp.WholeBodyCdmpParameters(S_hri=1.0),
                           time_step=time_step)
    for trial in range(12):
        context = system.CreateDefaultContext()
        scale = 10.0 ** rng.uniform(-3, 3)
        set_state(system, context, scale * rng.normal(size=24))
        fix_whole_body(system, context, rng, scale, connect=trial % 4 > 0)
        compare(system, context, 100 * scale)


def test_whole_body_cdmp_fast_path_playing_a_movement(player_stage):
    """Before, at and after the start time, across the movement's end,
    and over a period that starts just before the start time (the update
    plays, the output does not)."""
    system, rng = player_stage, np.random.default_rng(4)
    start = MOVEMENT.start_time
    times = [0.0, start - 0.004, start, start + 0.013, 2.0, 7.5, 30.0]
    for k, t in enumerate(times):
        context = system.CreateDefaultContext()
        context.SetTime(t)
        set_state(system, context, rng.normal(size=24))
        fix_whole_body(system, context, rng, 1.0, connect=k % 2 == 0)
        g, f = system.player.goal_and_forcing(t)
        compare(system, context, 100.0 + np.abs(np.r_[g, f]).max())


def test_the_deviation_reaches_only_the_update():
    system = WholeBodyCdmp()
    context = system.CreateDefaultContext()
    rng = np.random.default_rng(5)
    fix_whole_body(system, context, rng, 1.0, connect=True)
    output, update = fast_output(system, context), fast_update(system,
                                                               context)
    system.GetInputPort("end_effector_deviation").FixValue(
        context, rng.normal(size=6))
    np.testing.assert_array_equal(fast_output(system, context), output)
    assert not np.allclose(fast_update(system, context), update)
    compare(system, context, 100.0)


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_non_finite_inputs_stay_non_finite(value):
    """A non-finite input makes the fast path's output and update
    non-finite where the general path's are (so the checks downstream
    still see it)."""
    rng = np.random.default_rng(6)
    for make, port, size in ((ArmCdmp, "wrench", 6),
                             (BaseCdmp, "base_velocity", 3),
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
        for fast, general in ((fast_output, general_output),
                              (fast_update, general_update)):
            with np.errstate(invalid="ignore"):
                a, b = fast(system, context), general(system, context)
            assert not np.all(np.isfinite(a))
            np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b))


def test_converted_stages_take_the_general_path(player_stage):
    """AutoDiffXd takes the general path and gives the same values."""
    rng = np.random.default_rng(7)
    for system in (ArmCdmp(), BaseCdmp(), WholeBodyCdmp(), player_stage):
        converted = system.ToAutoDiffXd()
        assert system._fast and not converted._fast
        context = system.CreateDefaultContext()
        context.SetTime(1.2)
        context.SetDiscreteState(rng.normal(size=context.num_total_states()))
        ad_context = converted.CreateDefaultContext()
        ad_context.SetTime(AutoDiffXd(1.2))
        ad_context.SetDiscreteState(InitializeAutoDiff(
            context.get_discrete_state_vector().CopyToVector()).ravel())
        for i in range(system.num_input_ports()):
            port = system.get_input_port(i)
            if port.get_name() == "obstacle_points":
                value = AbstractValue.Make(rng.uniform(-1, 1, (30, 2)))
                port.FixValue(context, value)
                converted.get_input_port(i).FixValue(ad_context, value)
            else:
                value = rng.normal(size=port.size())
                port.FixValue(context, value)
                converted.get_input_port(i).FixValue(ad_context, value)
        values = [a.value() for a in converted.get_output_port(0).Eval(
            ad_context)]
        assert_close(fast_output(system, context), values, 100.0)
        update = converted.EvalUniquePeriodicDiscreteUpdate(
            ad_context).get_vector().CopyToVector()
        assert_close(fast_update(system, context),
                     [a.value() for a in update], 100.0)


def original_drive_terms(player, t):
    """[g; f] by the formulas of drake_wbc.math.dmp and np.interp."""
    if t < player.start_time - 1e-9:
        return np.zeros(12)
    elapsed = max(t - player.start_time, 0.0)
    s = float(dmp.canonical_phase(elapsed, player.params))
    f = np.zeros(6)
    f[[0, 1, 2, 5]] = dmp.forcing_term(s, player.movement.weights,
                                       player.params)
    p = np.interp(elapsed, player._times, player._progress)
    g = player.learned_goal + p * (player.goal - player.learned_goal)
    return np.concatenate([g, f])


def test_player_terms_and_reference(player_stage):
    player = player_stage.player
    rng = np.random.default_rng(9)
    grid = player._times
    times = np.concatenate([
        [0.0, player.start_time - 1e-10, player.start_time,
         player.start_time + grid[-1], player.start_time + grid[-1] + 3.0],
        player.start_time + grid[rng.integers(0, grid.size, 10)],
        rng.uniform(0.0, player.start_time + grid[-1], 30)])
    weight_scale = np.abs(player.movement.weights).max()
    for t in times:
        terms = player.drive_terms(t)
        assert_close(terms, original_drive_terms(player, t), weight_scale)
        g, f = player.goal_and_forcing(t)
        np.testing.assert_array_equal(np.r_[g, f], terms)
        elapsed = max(t - player.start_time, 0.0)
        expected = player.start + [np.interp(elapsed, grid,
                                             player._reference[:, i])
                                   for i in range(4)]
        assert_close(player.reference(t), expected, 1.0)
        progress = np.interp(elapsed, grid, player._progress)
        assert_close(player.goal_at(elapsed), player.learned_goal + progress
                     * (player.goal - player.learned_goal), 1.0)


def test_movement_tracking(player_stage, arm):
    """K (p* - p) on x, y, z and yaw (wrapped), from the pose of
    demonstration.TcpPose and np.interp of the played rollout."""
    player = player_stage.player
    system = MovementTracking(player, arm)
    context = system.CreateDefaultContext()
    rng, pose = np.random.default_rng(11), TcpPose(arm)
    for t in (0.2, 0.5, 1.7, 4.0, 20.0):
        context.SetTime(t)
        base = np.r_[rng.uniform(-1, 1, 2), rng.uniform(-4, 4),
                     np.zeros(3)]
        q = rng.uniform(arm.lower, arm.upper)
        system.GetInputPort("base.state_estimated").FixValue(context, base)
        system.GetInputPort("arm.position_measured").FixValue(context, q)
        expected = np.zeros(6)
        if t >= player.start_time:
            elapsed = t - player.start_time
            error = player.start + [
                np.interp(elapsed, player._times, player._reference[:, i])
                for i in range(4)] - pose(base[:3], q)
            error[3] = (error[3] + np.pi) % (2 * np.pi) - np.pi
            expected[[0, 1, 2, 5]] = player.tracking_gain * error
        assert_close(system.get_output_port(0).Eval(context), expected, 10.0)
    # The same values in AutoDiffXd.
    converted = system.ToAutoDiffXd()
    ad_context = converted.CreateDefaultContext()
    ad_context.SetTime(AutoDiffXd(t))
    for name, value in (("base.state_estimated", base),
                        ("arm.position_measured", q)):
        converted.GetInputPort(name).FixValue(ad_context, value)
    assert_close([v.value() for v in converted.get_output_port(0).Eval(
        ad_context)], expected, 10.0)
