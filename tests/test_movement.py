"""Learning, saving and playing a whole-body movement
(drake_wbc.math.movement),
and WholeBodyCdmp playing it against the DMP core's own integration."""

from dataclasses import replace

import numpy as np
import pytest
import yaml
from pydrake.autodiffutils import (
    AutoDiffXd,
    ExtractGradient,
    InitializeAutoDiff,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.primitives import Linearize

from drake_wbc.controller.task import Schedule
from drake_wbc.math import cdmp, dmp
from drake_wbc.math import movement as mv
from drake_wbc.math.demonstration import (
    Demonstration,
    TcpPose,
    teaching_interval,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import WholeBodyCdmp
from drake_wbc.stages.whole_body_cdmp import MovementTracking

START = np.array([0.9, 0.0, 0.65, -3.0])
GOAL = np.array([1.7, 0.35, 0.7, -2.7])


def synthetic(seed=0, num_basis=15, duration=4.0):
    """(params, weights, t, y): a rollout of dmp.rollout with random
    weights, from rest to rest (run on 2 s past the basis)."""
    rng = np.random.default_rng(seed)
    params = dmp.DmpParameters(duration=duration, num_basis=num_basis)
    weights = 20.0 * rng.normal(size=(num_basis, 4))
    t, y, _ = dmp.rollout(params, START, GOAL, duration + 2.0, 0.01,
                          weights)
    return params, weights, t, y


def rollout_error(movement, t, y):
    t_l, y_l, _ = movement.rollout(dt=0.01, extra_time=0.0)
    rolled = np.column_stack([np.interp(t, t_l, y_l[:, i])
                              for i in range(4)])
    return np.sqrt(np.mean((rolled - y) ** 2))


def test_a_rollout_is_recovered():
    params, weights, t, y = synthetic()
    learned = mv.learn_movement(Demonstration(t, y), params,
                                num_basis=40)
    assert learned.params.duration == pytest.approx(t[-1])
    np.testing.assert_allclose(learned.start, START)
    np.testing.assert_allclose(learned.goal, y[-1])
    # 0.1 % of the movement's 0.9 m (the learned basis spans the whole
    # rollout, not the generating one's).
    assert rollout_error(learned, t, y) < 1e-3


def test_zero_basis_functions_are_refused_not_replaced():
    params, _, t, y = synthetic()
    with pytest.raises(ValueError, match="num_basis = 0 is not allowed"):
        mv.learn_movement(Demonstration(t, y), params, num_basis=0)


def test_demonstrations_a_turn_apart_in_yaw_average_to_their_heading():
    # Each demonstration's yaw is unwrapped from its own first sample, so
    # two of one movement about the heading pi may start at 3.1 and
    # -3.18 rad (the same heading): their mean, -0.04 rad, was a start
    # and goal facing the other way.
    params, _, t, y = synthetic()
    turned = y - [0.0, 0.0, 0.0, 2.0 * np.pi]
    learned = mv.learn_movement([Demonstration(t, y),
                                 Demonstration(t, turned)], params,
                                num_basis=40)
    np.testing.assert_allclose(learned.start, y[0], atol=1e-12)
    np.testing.assert_allclose(learned.goal, y[-1], atol=1e-12)
    assert rollout_error(learned, t, y) < 1e-3


def test_several_noisy_demonstrations_average():
    params, _, t, y = synthetic(seed=1)
    rng = np.random.default_rng(2)
    demos = [Demonstration(t * (1.0 + 0.02 * k),
                              y + 1e-3 * rng.normal(size=y.shape))
             for k in range(6)]
    one = mv.learn_movement(demos[0], params, num_basis=40)
    several = mv.learn_movement(demos, params, num_basis=40)
    assert several.params.duration == pytest.approx(
        np.mean([d.duration for d in demos]))
    # Compare the shapes on the mean duration.
    scaled_t = t * several.params.duration / t[-1]
    error_one = rollout_error(one, t * one.params.duration / t[-1], y)
    error_several = rollout_error(several, scaled_t, y)
    assert error_several < error_one
    assert error_several < 5e-3


def test_save_and_load_round_trip(tmp_path):
    params, _, t, y = synthetic()
    base = np.column_stack([y[:, 0] - 0.9, y[:, 1], y[:, 3]])
    learned = mv.learn_movement(Demonstration(t, y, base), params,
                                source="a test")
    path = learned.save(tmp_path / "m.yaml")
    text = path.read_text()
    assert text.startswith("# A whole-body movement") and "a test" in text
    loaded = mv.LearnedMovement.load(path)
    np.testing.assert_allclose(loaded.weights, learned.weights, rtol=1e-5)
    np.testing.assert_allclose(loaded.start, learned.start, atol=1e-7)
    np.testing.assert_allclose(loaded.goal, learned.goal, atol=1e-7)
    assert loaded.params.resolved_alpha_s == pytest.approx(
        learned.params.resolved_alpha_s)
    assert loaded.params.num_basis == learned.params.num_basis
    demo = loaded.demonstrations[0]
    assert np.median(np.diff(demo.time)) == pytest.approx(mv.PLOT_PERIOD)
    assert demo.base.shape == (demo.time.size, 3)
    np.testing.assert_allclose(demo.tcp[-1], y[-1], atol=1e-5)


def test_teaching_interval_is_where_s_hri_is_one():
    schedule = Schedule(times=[0.0, 0.5, 6.5], values=[[0], [1], [0]])
    assert teaching_interval(schedule, 7.0) == (0.5, 6.5)
    assert teaching_interval(Schedule(), 7.0, 1.0) == (0.0, 7.0)
    with pytest.raises(ValueError, match="never 1"):
        teaching_interval(Schedule(), 7.0, 0.0)
    # Played linearly, S_hri passes 0.5 (on, for the stages) half way
    # between the times: the worker guides the robot from 1 s to 7 s, not
    # from 2 s to 8 s (which cut the demonstration's first second off).
    ramps = Schedule(times=[0.0, 2.0, 6.0, 8.0],
                     values=[[0], [1], [1], [0]], interpolation="linear")
    assert teaching_interval(ramps, 10.0) == (1.0, 7.0)


def movement_file(tmp_path):
    params, _, t, y = synthetic(duration=3.0)
    return mv.learn_movement(Demonstration(t, y), params).save(
        tmp_path / "m.yaml")


def test_player_is_silent_before_start_and_moves_the_goal_with_progress(
        tmp_path):
    learned = mv.LearnedMovement.load(movement_file(tmp_path))
    moved = learned.goal + [0.1, -0.1, 0.05, 2 * np.pi + 0.1]
    player = mv.MovementPlayer(learned, cdmp.MovementReplay(
        file="m", goal=list(moved), start_time=1.0))
    g, f = player.goal_and_forcing(0.99)
    assert not g.any() and not f.any()
    np.testing.assert_allclose(player.reference(0.5), learned.start)
    g, f = player.goal_and_forcing(1.0)
    # At the start, the learned goal; the move follows the progress.
    np.testing.assert_allclose(g[[0, 1, 2, 5]], learned.goal - learned.start)
    np.testing.assert_allclose(
        f[[0, 1, 2, 5]], dmp.forcing_term(1.0, learned.weights,
                                          learned.params))
    assert g[3] == g[4] == f[3] == f[4] == 0.0
    g, _ = player.goal_and_forcing(100.0)  # the yaw within a turn
    target = moved - learned.start - [0, 0, 0, 2 * np.pi]
    np.testing.assert_allclose(g[[0, 1, 2, 5]], target)
    np.testing.assert_allclose(player.reference(100.0),
                               learned.start + target, atol=1e-5)
    halfway = player.goal_at(0.5 * player.params.duration)[[0, 1, 2, 5]]
    assert np.all((halfway - g[[0, 1, 2, 5]]) * (
        halfway - (learned.goal - learned.start)) < 0)


@pytest.mark.parametrize("yaw", [
    np.zeros(401),  # at rest: the fit's rounding is all the rollout moves
    0.5 * np.sin(np.linspace(0.0, np.pi, 401)) + 0.01 * np.linspace(
        0.0, 1.0, 401),  # a turn out and (nearly) back on the spot
])
def test_a_moved_goal_of_a_movement_on_the_spot_is_reached_monotonically(
        yaw):
    # The progress p(t) must run from 0 to 1: a demonstration that does not
    # translate took it from the yaw's |y - y0| over its last value, which
    # at rest was the fit's rounding over rounding and after a turn out and
    # back peaked at 50, so the goal moved to 85 m and 10 m.
    t = np.linspace(0.0, 4.0, 401)
    tcp = np.column_stack([np.full(401, 1.0), np.full(401, 2.0),
                           np.full(401, 0.8), 0.2 + yaw])
    learned = mv.learn_movement(Demonstration(t, tcp))
    moved = learned.goal + [0.2, 0.0, 0.0, 0.0]
    player = mv.MovementPlayer(learned, cdmp.MovementReplay(
        file="m", goal=list(moved)))
    progress = np.asarray(player._progress) * np.ones(len(player._times))
    assert progress.min() >= 0.0 and progress.max() <= 1.0 + 1e-12
    assert np.all(np.diff(progress) >= 0.0)
    x = [player.reference(s)[0] for s in np.linspace(0.0, 9.0, 91)]
    assert max(x) < moved[0] + 1e-3
    assert x[-1] == pytest.approx(moved[0], abs=1e-3)


def test_whole_body_cdmp_plays_the_dmp_core_rollout(tmp_path):
    """Through its ports, WholeBodyCdmp with a movement (no coupling
    input) moves as dmp.rollout integrates the same DMP, from its
    start_time on, to a moved goal and with temporal scaling."""
    path = movement_file(tmp_path)
    learned = mv.LearnedMovement.load(path)
    goal = learned.goal + [0.1, -0.05, 0.02, 0.1]
    start_time, tau = 0.5, 1.3
    params = cdmp.WholeBodyCdmpParameters(movement=cdmp.MovementReplay(
        file=str(path), goal=list(goal), start_time=start_time, tau=tau))
    system = WholeBodyCdmp(params, time_step=0.01)
    context = system.CreateDefaultContext()
    for name in ("reference_velocity", "wrench", "end_effector_deviation"):
        system.GetInputPort(name).FixValue(context, np.zeros(6))
    simulator = Simulator(system, context)
    output = system.GetOutputPort("end_effector_velocity")
    player = system.player
    times = start_time + np.arange(0.0, 5.0, 0.25)
    velocities, positions = [], []
    for t in times:
        simulator.AdvanceTo(t)
        velocities.append(output.Eval(context)[[0, 1, 2, 5]])
        positions.append(context.get_discrete_state_vector().
                         CopyToVector()[[0, 1, 2, 5]])
    displacement = goal - learned.start

    def moving_goal(t):
        return player.goal_at(t)[[0, 1, 2, 5]]

    t_r, y_r, yd_r = dmp.rollout(learned.params, np.zeros(4), None, 5.0,
                                 0.001, learned.weights, moving_goal, tau)
    k = np.searchsorted(t_r, times - start_time - 1e-9)
    np.testing.assert_allclose(positions, y_r[k], atol=5e-4)
    np.testing.assert_allclose(velocities, yd_r[k], atol=2e-3)
    # On its way to the moved goal (the phase is at 0.02 at the end).
    assert np.all(np.abs(positions[-1] - displacement)
                  < 0.1 * np.abs(displacement))
    # Still scalar-convertible, and silent before start_time.
    assert system.ToAutoDiffXd().player is player
    assert not np.any(player.goal_and_forcing(0.49)[0])
    # Linearize runs on it, playing (the movement's tau in A) or not.
    for t, playing in ((start_time + 1.0, True), (0.2, False)):
        context.SetTime(t)
        linear = Linearize(
            system, context,
            input_port_index=system.GetInputPort(
                "reference_velocity").get_index(),
            output_port_index=output.get_index(),
            equilibrium_check_tolerance=1e9)
        np.testing.assert_allclose(linear.A(),
                                   system._models[(0, playing)].A_d)


def test_a_faster_replay_is_the_same_path_sooner(tmp_path):
    """Played at tau = tau_0 / 50, the player's reference is its own at
    tau_0 with time 50 times faster (the exact temporal scaling of eqs.
    (6), (7), drake_wbc.math.dmp): its rollouts take steps that resolve
    the faster attractor (with the fixed 5 ms step, 0.25 of the
    Runge-Kutta step's stability limit at tau_0, the reference grew to
    1e49 m)."""
    learned = mv.LearnedMovement.load(movement_file(tmp_path))
    slow = mv.MovementPlayer(learned, cdmp.MovementReplay(file="m"))
    fast = mv.MovementPlayer(learned, cdmp.MovementReplay(file="m",
                                                          tau=0.02))
    for u in np.linspace(0.0, 1.5, 31):
        np.testing.assert_allclose(
            fast.reference(u * fast.params.duration),
            slow.reference(u * slow.params.duration), atol=1e-6)


def test_a_replay_too_fast_or_too_long_is_refused(tmp_path):
    """A tau or a movement's duration whose rollouts would take more
    than MAX_ROLLOUT_STEPS steps is refused when the player is built,
    naming the value (a tau of tau_0 / 1000 gave a reference of NaN; a
    duration of 1e300 s, in a file, an error from numpy's arange)."""
    learned = mv.LearnedMovement.load(movement_file(tmp_path))
    with pytest.raises(ValueError, match=r"tau = 0\.001 is not allowed "
                       r"for the movement m .*play it slower"):
        mv.MovementPlayer(learned, cdmp.MovementReplay(file="m", tau=1e-3))
    path = tmp_path / "long.yaml"
    path.write_text(movement_file(tmp_path).read_text().replace(
        "duration: 5.0", "duration: 1.0e+300"))
    with pytest.raises(ValueError, match=r"long\.yaml: dmp\.duration = "
                       r"1e\+300 s .*not allowed: a movement lasts at most "
                       r"495 s"):
        mv.MovementPlayer(mv.LearnedMovement.load(path),
                          cdmp.MovementReplay(file=str(path)))
    # Played 200 times slower, the 5 s movement would last 1000 s: the
    # tau is what is refused, named as the caller calls it.
    with pytest.raises(ValueError, match=r"^--tau = 200\.0 is not allowed "
                       r"for the movement m \(learned at tau = 1 over 5 s\): "
                       r"played 200 times slower, it would last 1000 s, at "
                       r"most 495 s .*play it faster \(a smaller tau\)$"):
        mv.rollout_step(learned, 200.0, source="m", name="--tau")
    assert mv.rollout_step(learned, 1.0) == 0.005
    # MAX_ROLLOUT_STEPS' bound for the shipped 6 s movement.
    shipped = mv.LearnedMovement.load(mv.resolve_movement_file(
        "movements/teach.yaml"))
    assert mv.rollout_step(shipped, 1.0 / 198.0) > 0.0
    with pytest.raises(ValueError, match="200 times faster"):
        mv.rollout_step(shipped, 1.0 / 200.0)
    # A 1000 s movement played twice as fast still lasts 500 s: faster,
    # not "0.5 times slower".
    long = replace(learned, params=replace(learned.params, duration=1000.0))
    with pytest.raises(ValueError, match=r"^tau = 0\.5 is not allowed .*"
                       r"played 2 times faster, it would last 500 s, at "
                       r"most 495 s .*play it faster \(a smaller tau\)$"):
        mv.rollout_step(long, 0.5)


BOMB = """dmp: {alpha_z: 25.0, duration: 5.0, num_basis: 2}
start: [0, 0, 0, 0]
goal: [0, 0, 0, 0]
a: &a [0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a, *a]
c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b, *b]
d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]
e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d, *d]
weights: [*e, *e]
"""
"""Two million zeros in 60 aliases: each level more multiplies them by
ten (nine levels would fill the memory)."""


def test_a_hostile_movement_file_is_refused_before_it_is_built(tmp_path):
    """A movement file is read as the scenarios are
    (drake_wbc.math.loading): an alias bomb and a file over MAX_BYTES are
    refused before anything is built (the weights of BOMB were expanded
    into 2e6 numbers, 1 s and 80 MB, before their shape was refused; a
    1.4 MB file was read), and what does not fit says which field (an
    empty file said "'NoneType' object is not subscriptable", a
    demonstration without tcp "'tcp'", a time that goes back printed
    every time)."""
    good = movement_file(tmp_path).read_text()

    def refused(text, match):
        path = tmp_path / "hostile.yaml"
        path.write_text(text)
        with pytest.raises(ValueError, match=match):
            mv.LearnedMovement.load(path)

    refused(BOMB, r"hostile\.yaml: line 8, .*aliases expanded")
    refused(good + "# " + "x" * (1 << 20) + "\n",
            r"more than 1048576 bytes is not allowed")
    refused("", r"the document = None is not allowed: must be a mapping "
            "of dimensions, dmp, start, goal, weights and demonstrations")
    refused(good.replace("weights:", "weight:"), r"weights is missing")
    refused(good.replace("dimensions: [x, y, z, yaw]",
                         "dimensions: [yaw, x, y, z]"),
            r"dimensions = \['yaw', 'x', 'y', 'z'\] is not allowed")
    refused(good.replace("  tcp:", "  pose:"),
            r"demonstrations\[0\] = \{time: .* is not allowed: must be a "
            "mapping of time, tcp")
    document = yaml.safe_load(good)
    times = document["demonstrations"][0]["time"]
    times[5] = times[2]
    refused(yaml.safe_dump(document),
            rf"demonstrations\[0\]\.time\[5\] = {times[2]!r} s is not "
            rf"allowed: the times must increase strictly \(time\[4\] = "
            rf"{times[4]!r} s; 1 of the {len(times)} samples do not\)")


def test_a_long_demonstration_is_kept_within_what_the_loader_reads(
        tmp_path):
    """A demonstration of 600 s at 100 Hz is saved at a longer period
    than PLOT_PERIOD, within MAX_KEPT_SAMPLES and its last sample kept,
    so that the file loads (at PLOT_PERIOD it held 12,000 samples,
    beyond the loader's MAX_NODES)."""
    t = np.arange(60001) * 0.01
    y = START + np.outer(0.5 - 0.5 * np.cos(np.pi * t / t[-1]),
                         GOAL - START)
    learned = mv.learn_movement(Demonstration(t, y), num_basis=20)
    loaded = mv.LearnedMovement.load(learned.save(tmp_path / "long.yaml"))
    demo = loaded.demonstrations[0]
    assert 3000 < demo.time.size <= mv.MAX_KEPT_SAMPLES
    assert demo.time[-1] == pytest.approx(600.0)
    np.testing.assert_allclose(demo.tcp[-1], GOAL, atol=1e-5)


def test_bad_movement_parameters_are_explained(tmp_path):
    with pytest.raises(ValueError, match=r"tau = -1.*greater than 0|tau"):
        cdmp.MovementReplay(file="m.yaml", tau=-1.0)
    with pytest.raises(ValueError, match="goal"):
        cdmp.MovementReplay(file="m.yaml", goal=[1.0, 2.0])
    with pytest.raises(ValueError, match="start_time"):
        cdmp.MovementReplay(file="m.yaml", start_time=-0.5)
    with pytest.raises(ValueError, match="movement = 3"):
        cdmp.WholeBodyCdmpParameters(movement=3)
    missing = cdmp.WholeBodyCdmpParameters(
        movement=cdmp.MovementReplay(file="no/such/movement.yaml"))
    with pytest.raises(ValueError, match=r"movement\.file = 'no/such/"
                       r"movement\.yaml'.*no movement file"):
        WholeBodyCdmp(missing)
    with pytest.raises(ValueError, match="must name"):
        WholeBodyCdmp(cdmp.WholeBodyCdmpParameters(
            movement=cdmp.MovementReplay()))
    bad = tmp_path / "bad.yaml"
    bad.write_text("weights: [1, 2]\n")
    with pytest.raises(ValueError, match="not a learned movement"):
        mv.LearnedMovement.load(bad)
    with pytest.raises(ValueError, match="demonstrations"):
        mv.learn_movement([])
    with pytest.raises(ValueError, match="time"):
        Demonstration([0.0, 0.0, 1.0], np.zeros((3, 4)))


MOVEMENT = cdmp.MovementReplay(file="movements/teach.yaml", start_time=0.5,
                               goal=[1.7, 0.3, 0.7, -2.9], tau=1.3)
"""The committed movement, to a moved goal and slower."""


@pytest.fixture(scope="module")
def player_stage():
    return WholeBodyCdmp(cdmp.WholeBodyCdmpParameters(movement=MOVEMENT))


def terms_as_written(player, t):
    """[g; f] by the formulas of drake_wbc.math.dmp and np.interp: f(s) at
    the closed-form phase of t - start_time, g = g_0 + p(t) (g - g_0)."""
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
        np.testing.assert_allclose(terms, terms_as_written(player, t),
                                   rtol=1e-12, atol=1e-12 * weight_scale)
        g, f = player.goal_and_forcing(t)
        np.testing.assert_array_equal(np.r_[g, f], terms)
        elapsed = max(t - player.start_time, 0.0)
        expected = player.start + [np.interp(elapsed, grid,
                                             player._reference[:, i])
                                   for i in range(4)]
        np.testing.assert_allclose(player.reference(t), expected,
                                   rtol=1e-12, atol=1e-12)


def test_whole_body_cdmp_plays_g_and_f_of_the_period(player_stage):
    """The output takes the movement's g and f at the context's time, the
    update at the middle of the period: before, at and after the start
    time, across the movement's end, and over a period that starts just
    before the start time (the update plays, the output does not)."""
    system, rng = player_stage, np.random.default_rng(4)
    player, h = system.player, system._time_step
    start = MOVEMENT.start_time
    for t in [0.0, start - 0.004, start, start + 0.013, 2.0, 7.5, 30.0]:
        context = system.CreateDefaultContext()
        context.SetTime(t)
        x = rng.normal(size=24)
        context.SetDiscreteState(x)
        V_ref, F = rng.normal(size=6), 100 * rng.normal(size=6)
        for name, value in (("reference_velocity", V_ref), ("wrench", F),
                            ("end_effector_deviation", np.zeros(6))):
            system.GetInputPort(name).FixValue(context, value)

        def model_and_inputs(time, V_ref=V_ref, F=F):
            key = (0, player.active(time))
            return system._models[key], np.concatenate(
                [V_ref, F, np.zeros(6), player.drive_terms(time)])

        model, u = model_and_inputs(t)
        size = 100.0 + np.abs(u).max()
        np.testing.assert_allclose(
            system.get_output_port().Eval(context),
            model.derivative(x, u)[:6], rtol=1e-12, atol=1e-12 * size)
        model, u = model_and_inputs(t + 0.5 * h)
        np.testing.assert_allclose(
            system.EvalUniquePeriodicDiscreteUpdate(
                context).get_vector().CopyToVector(),
            model.next_state(x, u), rtol=1e-12, atol=1e-12 * size)


def test_movement_tracking(player_stage):
    """K (p* - p) on x, y, z and yaw (wrapped), p from
    demonstration.TcpPose and p* from np.interp of the played rollout;
    the same values in AutoDiffXd."""
    arm = ArmKinematics()
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
        np.testing.assert_allclose(system.get_output_port(0).Eval(context),
                                   expected, rtol=1e-12, atol=1e-11)
    converted = system.ToAutoDiffXd()
    ad_context = converted.CreateDefaultContext()
    ad_context.SetTime(AutoDiffXd(t))
    for name, value in (("base.state_estimated", base),
                        ("arm.position_measured", q)):
        converted.GetInputPort(name).FixValue(ad_context, value)
    np.testing.assert_allclose([v.value() for v in converted.get_output_port(
        0).Eval(ad_context)], expected, rtol=1e-12, atol=1e-11)
    # Its derivatives, while playing: the AutoDiffXd copy's w.r.t. the
    # base's state and the arm's joints, and Drake's Linearize (D), both
    # against central differences of the double system (the copy once
    # gave the error without derivatives: no feedback of the TCP's pose
    # in a linearisation of the replay).
    context.SetTime(1.7)
    ad_context.SetTime(AutoDiffXd(1.7))
    inputs = dict(base=base, q=q)
    step = 1e-6
    for name, key in (("base.state_estimated", "base"),
                      ("arm.position_measured", "q")):
        port = system.GetInputPort(name)
        value = inputs[key]
        columns = []
        for e in np.eye(value.size):
            ends = []
            for sign in (1.0, -1.0):
                port.FixValue(context, value + sign * step * e)
                ends.append(system.get_output_port(0).Eval(context).copy())
            columns.append((ends[0] - ends[1]) / (2 * step))
        port.FixValue(context, value)
        central = np.column_stack(columns)
        assert np.abs(central).max() > 0.1
        seeded = InitializeAutoDiff(value).ravel()
        converted.GetInputPort(name).FixValue(ad_context, seeded)
        np.testing.assert_allclose(ExtractGradient(
            converted.get_output_port(0).Eval(ad_context)), central,
            atol=1e-6)
        converted.GetInputPort(name).FixValue(ad_context, value)
        linear = Linearize(system, context, input_port_index=port.get_index(),
                           output_port_index=system.get_output_port(
                               0).get_index())
        np.testing.assert_allclose(linear.D(), central, atol=1e-6)


def test_tcp_pose_is_the_plants():
    """TcpPose against the TCP's pose from the plant and a rotation of the
    base by its yaw, with RigidTransforms."""
    from pydrake.math import RigidTransform, RotationMatrix

    arm = ArmKinematics()
    pose = TcpPose(arm)
    model = arm.model
    X_BA = model.arm_base_frame.CalcPose(arm.plant.CreateDefaultContext(),
                                         model.base_frame)
    rng = np.random.default_rng(12)
    for _ in range(10):
        base = np.r_[rng.uniform(-1, 1, 2), rng.uniform(-4, 4)]
        q = rng.uniform(arm.lower, arm.upper)
        X_WB = RigidTransform(RotationMatrix.MakeZRotation(base[2]),
                              [base[0], base[1], 0.0])
        X_WT = X_WB @ X_BA @ arm.frame_pose(q, model.tcp_frame)
        R = X_WT.rotation().matrix()
        np.testing.assert_allclose(
            pose(base, q), np.r_[X_WT.translation(),
                                 np.arctan2(R[1, 0], R[0, 0])],
            rtol=0, atol=1e-14)


def _stub_station(num_joints):
    """A Diagram with the station's ports: constant measurements out
    (controller.diagram.STATION_INPUTS), the two commands into sinks."""
    from pydrake.common.value import AbstractValue
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import (
        ConstantValueSource,
        ConstantVectorSource,
        VectorLogSink,
    )

    builder = DiagramBuilder()
    for name, size in (("base.state_estimated", 6),
                       ("arm.position_measured", num_joints),
                       ("wrist.wrench_measured", 6)):
        source = builder.AddSystem(ConstantVectorSource(np.zeros(size)))
        builder.ExportOutput(source.get_output_port(), name)
    points = builder.AddSystem(ConstantValueSource(
        AbstractValue.Make(np.zeros((0, 2)))))
    builder.ExportOutput(points.get_output_port(), "lidar.obstacle_points")
    for name, size in (("base.velocity_command", 3),
                       ("arm.position_command", num_joints)):
        sink = builder.AddSystem(VectorLogSink(size))
        builder.ExportInput(sink.get_input_port(), name)
    return builder.Build()


@pytest.mark.parametrize("given", ["description", "none"])
def test_the_tasks_tracking_uses_the_controllers_arm(given):
    """add_controller with a learned movement to track: the task's
    MovementTracking measures the TCP with the controller's own
    ArmKinematics, whether the caller gave a RobotDescription or
    nothing."""
    from pydrake.systems.framework import DiagramBuilder

    from drake_wbc.controller.parameters import ControllerParameters
    from drake_wbc.controller.task import TaskInputs, add_controller
    from drake_wbc.robot.description import shipped_robot

    robot = shipped_robot()
    params = ControllerParameters()
    params.whole_body_cdmp.movement = MOVEMENT
    builder = DiagramBuilder()
    station = builder.AddNamedSystem(
        "station", _stub_station(robot.num_arm_joints))
    controller, _ = add_controller(
        builder, params, TaskInputs(), station,
        arm=robot if given == "description" else None)
    tracking = builder.GetSubsystemByName("task.movement_tracking")
    assert isinstance(tracking, MovementTracking)
    assert tracking._pose.arm is controller.arm
    assert tracking.GetInputPort("arm.position_measured").size() == (
        controller.arm.num_joints)


def test_movement_tracking_refuses_what_is_not_an_arm_kinematics(
        player_stage):
    """A RobotDescription (or anything but an ArmKinematics or None) is
    refused naming the argument, not failed on later."""
    from drake_wbc.robot.description import shipped_robot

    for arm in (shipped_robot(), "arm"):
        with pytest.raises(ValueError, match=r"arm = .* ArmKinematics"):
            MovementTracking(player_stage.player, arm)
