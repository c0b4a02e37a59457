"""drake-wbc bench: the quick run writes well-formed tables; the race is
fair (every same-problem contender returns the same V_wb); the tick loop
does one discrete update a tick, on measurements new every tick, and
pulls the station's commands; with --robot, all of it on the second
shipped robot (a 7-joint arm on another base)."""

import argparse
import json

import numpy as np
import pytest

from drake_wbc.bench import add_bench_arguments, run_bench
from drake_wbc.bench import distribution_race as race
from drake_wbc.bench.commands import FAIRNESS_TOLERANCE
from drake_wbc.bench.report import GOALS
from drake_wbc.math import distribution, kinematics
from drake_wbc.robot.description import load_robot_description, models_dir
from drake_wbc.robot.model import ArmKinematics, make_robot_plant

LBR_FILE = models_dir() / "lbr_omni.robot.yaml"
"""The second shipped robot's description: a 7-joint arm."""
UR_FILE = models_dir() / "ur_omni.robot.yaml"
"""The third shipped robot's description: a UR5e-class arm."""


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


@pytest.fixture(scope="module")
def lbr():
    return ArmKinematics(*make_robot_plant(load_robot_description(LBR_FILE)))


@pytest.fixture(scope="module")
def ur():
    return ArmKinematics(*make_robot_plant(load_robot_description(UR_FILE)))


@pytest.fixture(params=["arm", "lbr", "ur"])
def either(request):
    """The shipped robot's arm, then the 7-joint one, then the UR-class
    one."""
    return request.getfixturevalue(request.param)


def test_quick_bench_writes_well_formed_tables(tmp_path):
    parser = argparse.ArgumentParser()
    add_bench_arguments(parser)
    args = parser.parse_args(["--quick", "--output", str(tmp_path),
                              "--repeats", "2"])
    printed = []
    assert run_bench(args, echo=printed.append) == 0
    results = json.loads((tmp_path / "bench.json").read_text())
    assert set(results) == {"environment", "settings", "robot",
                            "distribution", "control_tick", "scaling",
                            "scenarios", "goals"}
    assert results["robot"] == {"name": "mcr", "arm_joints": 6}
    assert results["settings"]["robot"] is None
    env = results["environment"]
    assert env["packages"]["drake"] and env["packages"]["numpy"]
    assert env["cpu_count"] >= 1 and env["cpu_model"] and env["python"]
    race_results = results["distribution"]
    assert race_results["fair"]
    solve = race_results["solve"]
    assert {"closed_form", "daqp", "proxsuite", "quadprog", "drake_diffik",
            "qpsolvers_osqp", "qpsolvers_clarabel"} <= set(solve)
    contenders = race_results["with_kinematics"]
    assert set(contenders) == set(solve) | {"drake_diffik_plant"}
    for entry in [*solve.values(), *contenders.values(),
                  race_results["kinematics"], race_results["qp_data"]]:
        for stats in (entry["time_us"], entry["cpu_us"]):
            assert stats["n"] == 2
            assert 0 < stats["p10"] <= stats["median"] <= stats["p90"]
    tick = results["control_tick"]
    assert tick["tick"]["time_us"]["median"] > 0
    assert tick["tick"]["cpu_us"]["median"] > 0
    assert tick["framework_floor"]["time_us"]["median"] > 0
    assert set(tick["stages"]) >= {"capability", "distributor",
                                   "base_cdmp", "arm_controller"}
    assert [e["points"] for e in results["scaling"]["obstacle_points"]] \
        == [100, 2000]
    assert [e["rate_hz"] for e in results["scaling"]["control_rate"]] \
        == [100.0, 1000.0]
    run = results["scenarios"]["trajectory_tracking"]
    assert run["real_time_factor"] > 0 and run["peak_memory_mib"] > 50
    assert run["runs"][0]["robot"] == "mcr"
    assert [g["goal"] for g in results["goals"]] == [g[0] for g in GOALS]
    assert all(isinstance(g["met"], bool) for g in results["goals"])

    text = (tmp_path / "bench.md").read_text()
    assert text in printed
    tables = [line for line in text.splitlines() if line.startswith("|")]
    for name in contenders:
        assert sum(line.startswith(f"| {name} |") for line in tables) == (
            2 if name in solve else 1), name
    for name, entry in tick["stages"].items():
        # Each stage beside its hollow twin: the rest is its own work.
        own = (entry["tick"]["time_us"]["median"]
               - entry["hollow"]["time_us"]["median"])
        row = next(line for line in tables
                   if line.startswith(f"| stage {name} |"))
        assert entry["hollow"]["time_us"]["median"] > 0, name
        assert row.rstrip(" |").endswith(f"| {own:.1f}"), row
    assert any(line.startswith("| trajectory_tracking |")
               for line in tables)
    tick_goal = next(line for line in tables
                     if line.startswith("| a full control tick"))
    median = tick["tick"]["time_us"]["median"]
    assert f"| {median:.0f} us (median) |" in tick_goal
    # Every table's rows have as many cells as its header.
    blocks, block = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            block.append(line)
        elif block:
            blocks.append(block)
            block = []
    assert len(blocks) == 7
    for rows in blocks:
        assert len({row.count("|") for row in rows}) == 1, rows[0]


@pytest.mark.filterwarnings("ignore:The default value of raise_error")
def test_contenders_agree_without_active_constraints(either):
    arm = either
    problems = race.make_problems(12, seed=7, arm=arm)
    given = race.given_data(arm, problems)
    solvers = race.make_solvers(arm)
    assert {"daqp", "proxsuite", "quadprog", "drake_diffik"} <= set(solvers)
    informative = {"drake_diffik_plant": race.PlantDiffIk(arm)}
    report = race.fairness(problems, solvers, given, informative)
    assert set(report) == set(solvers) | set(informative)
    for name in solvers:
        assert report[name]["max_abs_difference"] < FAIRNESS_TOLERANCE, name
    # The closed form itself satisfies the task: J_wb V_wb = V_ee.
    solve = solvers[race.REFERENCE]
    for problem in problems:
        p_ee = arm.evaluate(problem.arm_position).p_ee_in_base
        J = kinematics.whole_body_jacobian(None, p_ee, arm.R_ba)
        np.testing.assert_allclose(J @ solve(problem, race.Given(p_ee)),
                                   problem.end_effector_velocity,
                                   atol=1e-12)


@pytest.mark.filterwarnings("ignore:The default value of raise_error")
def test_with_kinematics_is_the_solve_at_the_plant_s_p_ee(arm):
    """Each contender with its kinematics gives what it gives from the
    data prepared beforehand, and that data is the checked functions'."""
    problems = race.make_problems(5, seed=11, arm=arm)
    given = race.given_data(arm, problems)
    for problem, data in zip(problems, given, strict=True):
        p_ee = arm.evaluate(problem.arm_position).p_ee_in_base
        np.testing.assert_array_equal(data.p_ee, p_ee)
        np.testing.assert_array_equal(
            data.J_wb, kinematics.whole_body_jacobian(None, p_ee, arm.R_ba))
        np.testing.assert_array_equal(np.diag(data.weights),
                                      distribution.weighting_matrix(
                                          problem.sigma_xy,
                                          problem.sigma_phi))
        np.testing.assert_array_equal(
            data.null_velocity, distribution.capability_null_velocity(
                problem.capability_gradient, problem.null_space_gain))
    for name, solve in race.make_solvers(arm, solvers=()).items():
        scratch = race.with_kinematics(arm, solve)
        for problem, data in zip(problems, given, strict=True):
            np.testing.assert_array_equal(scratch(problem),
                                          solve(problem, data), name)


def test_an_unfair_race_stops_before_timing(arm, monkeypatch):
    """A contender that solves another problem (V_ee scaled) makes the
    bench raise instead of timing it."""
    make_solvers = race.make_solvers

    def with_a_wrong_one(arm, *args, **kwargs):
        solvers = make_solvers(arm, solvers=())
        daqp = solvers["daqp"]
        solvers["daqp"] = lambda problem, given: 1.001 * daqp(problem,
                                                              given)
        return solvers

    monkeypatch.setattr(race, "make_solvers", with_a_wrong_one)
    from drake_wbc.bench.commands import bench_distribution

    with pytest.raises(RuntimeError, match="daqp"):
        bench_distribution(arm, dict(problems=3, seed=0, repeats=1))


@pytest.mark.filterwarnings("ignore:The default value of raise_error")
def test_scaled_diffik_is_the_weighted_least_norm_problem(either):
    """Independent of the controller's code: the weighted problem's KKT
    system, solved directly, gives what every contender gives (9
    variables and 6 equalities on the 7-joint arm as on six joints: the
    arm's input is its twist)."""
    arm = either
    problem = race.make_problems(1, seed=3, arm=arm)[0]
    assert race.problem_size(arm) == (9, 6)
    p_ee = arm.evaluate(problem.arm_position).p_ee_in_base
    J = kinematics.whole_body_jacobian(None, p_ee, arm.R_ba)
    W = np.diag(1.0 / np.diag(distribution.weighting_matrix(
        problem.sigma_xy, problem.sigma_phi)))
    V_n = np.concatenate([problem.null_space_gain
                          * problem.capability_gradient, np.zeros(3)])
    kkt = np.block([[W, J.T], [J, np.zeros((6, 6))]])
    rhs = np.concatenate([W @ V_n, problem.end_effector_velocity])
    expected = np.linalg.solve(kkt, rhs)[:9]
    given = race.given_data(arm, [problem])[0]
    for name, solve in race.make_solvers(arm).items():
        np.testing.assert_allclose(solve(problem, given), expected,
                                   atol=1e-7, err_msg=name)


def test_the_hollow_controller_has_the_controller_s_structure(arm):
    """The framework floor's diagram: every stage hollow, with the same
    ports, feedthrough, state and connections, and it ticks."""
    from drake_wbc.bench.control_tick import ControllerTicker
    from drake_wbc.bench.framework_floor import FloorTicker

    ticker = ControllerTicker(arm, num_points=50)
    floor = FloorTicker(ticker)
    assert floor.ticks(3)() == 3
    stages = ticker.controller.stages
    for name, stage in stages.items():
        hollow = floor.diagram.GetSubsystemByName(name)
        for get, count in (("get_input_port", "num_input_ports"),
                           ("get_output_port", "num_output_ports")):
            assert getattr(hollow, count)() == getattr(stage, count)()
            for i in range(getattr(stage, count)()):
                ours, theirs = (getattr(s, get)(i) for s in (hollow, stage))
                assert ours.get_name() == theirs.get_name()
                assert ours.get_data_type() == theirs.get_data_type()
        for i in range(stage.num_input_ports()):
            for j in range(stage.num_output_ports()):
                assert hollow.HasDirectFeedthrough(i, j) == \
                    stage.HasDirectFeedthrough(i, j), (name, i, j)
        ours = hollow.GetMyContextFromRoot(floor.context)
        theirs = stage.GetMyContextFromRoot(ticker.context)
        assert ours.num_discrete_state_groups() == \
            theirs.num_discrete_state_groups()
    names = {id(s): n for n, s in stages.items()}
    hollow_names = {id(floor.diagram.GetSubsystemByName(n)): n
                    for n in stages}

    def wiring(diagram, by_id):
        return {(by_id[id(d)], i, by_id[id(s)], j) for (d, i), (s, j)
                in diagram.connection_map().items()}

    assert wiring(floor.diagram, hollow_names) == wiring(
        ticker.controller.diagram, names)


def test_every_batch_of_ticks_starts_from_the_initial_state():
    from drake_wbc.bench.control_tick import ControllerTicker

    ticker = ControllerTicker(ArmKinematics(), num_points=50)
    port = ticker.controller.diagram.GetOutputPort("arm.position_command")
    start = port.Eval(ticker.context).copy()
    batch = ticker.ticks(4)
    batch()
    first = port.Eval(ticker.context).copy()
    assert np.abs(first - start).max() > 1e-4  # the ticks move the arm
    for _ in range(9):
        batch()
    # Ten batches end where the first did (to 1e-6): four ticks from
    # the start, not forty.
    np.testing.assert_allclose(port.Eval(ticker.context), first, atol=1e-6)
    for _ in range(36):
        ticker.advance()  # without the restart: the arm drifts on
    assert np.abs(port.Eval(ticker.context) - first).max() > 1e-2


def test_every_tick_does_exactly_one_update():
    """AdvanceTo((k + 1) h): over 1000 ticks (after restarts too) each
    does one discrete update; adding h to the context's time, as the
    bench did, gives some ticks two and others none."""
    from drake_wbc.bench.control_tick import ControllerTicker

    ticker = ControllerTicker(ArmKinematics(), num_points=20)
    simulator = ticker.simulator

    def updates_of_each_tick(advance, ticks):
        counts = []
        for _ in range(ticks):
            before = simulator.get_num_discrete_updates()
            advance()
            counts.append(simulator.get_num_discrete_updates() - before)
        return counts

    batch = ticker.ticks(3)
    batch()
    batch()
    assert updates_of_each_tick(ticker.advance, 1000) == [1] * 1000
    assert ticker.context.get_time() == 1003 * ticker.time_step
    ticker.restart()

    def by_adding_h():
        simulator.AdvanceTo(ticker.context.get_time() + ticker.time_step)

    counts = updates_of_each_tick(by_adding_h, 1000)
    assert sum(counts) == 1000 and set(counts) == {0, 1, 2}


def test_the_measurements_are_new_every_tick():
    """Each tick writes a measurement set that differs from the last in
    every entry (the arm's joints included), the tool's weight at that
    configuration on the wrist; no arm configuration comes back within
    a cycle."""
    from drake_wbc.bench.control_tick import ControllerTicker
    from drake_wbc.controller.diagram import STATION_INPUTS
    from drake_wbc.stages.wrench import tool_weight_reading

    arm = ArmKinematics()
    ticker = ControllerTicker(arm, num_points=20, measurement_sets=12)
    guard = ticker.controller.stages["guard"]
    inner = guard.GetMyContextFromRoot(ticker.context)
    ports = [guard.GetInputPort(name) for name in STATION_INPUTS]

    def seen():
        values = [port.Eval(inner) for port in ports]
        values[-1] = np.array(values[-1])  # the points
        return values

    ticker.restart()
    written = []
    for _ in range(24):
        ticker.advance()
        written.append(seen())
    for before, after in zip(written, written[1:], strict=False):
        for a, b in zip(before, after, strict=True):
            assert np.all(a != b)
    q = [values[1] for values in written]
    assert len({tuple(x) for x in q[:12]}) == 12
    np.testing.assert_array_equal(q[12:], q[:12])  # the cycle
    for values in written:
        np.testing.assert_allclose(values[2],
                                   tool_weight_reading(arm, values[1]),
                                   atol=1e-12)


def test_the_ticks_time_a_running_controller(either):
    """The ticker's arm measurements do not follow its commands (no
    plant): with the guard's arm-follow check at its default, the
    controller stopped some 1.5 s into every batch of ticks, so the bench
    timed a stopped controller for a quarter of them. The check runs,
    at a tolerance wider than any arm's travel."""
    from drake_wbc.bench.control_tick import ControllerTicker

    ticker = ControllerTicker(either, num_points=20)
    ticker.restart()
    for _ in range(300):
        ticker.advance()
        assert ticker.controller.safety_reason(ticker.context) == ""


def test_a_tick_pulls_the_station_s_commands():
    """After a tick, the exported commands are computed already: the
    ports' cache entries are up to date (pulling them again computes
    nothing), and without the pull they are not."""
    from drake_wbc.bench.control_tick import (
        STATION_COMMANDS,
        ControllerTicker,
    )

    ticker = ControllerTicker(ArmKinematics(), num_points=20)
    diagram = ticker.controller.diagram
    for name in STATION_COMMANDS:
        assert diagram.HasOutputPort(name)

    def up_to_date():
        states = []
        for name in STATION_COMMANDS:
            port = diagram.GetOutputPort(name)
            source, j = diagram.get_output_port_locator(port.get_index())
            inner = source.GetMyContextFromRoot(ticker.context)
            entry = source.get_output_port(j).cache_entry()
            states.append(not entry.is_out_of_date(inner))
        return states

    ticker.restart()
    ticker.advance(pull=False)
    assert not any(up_to_date())
    ticker.advance()
    assert all(up_to_date())


@pytest.mark.filterwarnings("ignore:The default value of raise_error")
def test_the_joint_space_peer_takes_eq_wbccm_at_the_arm_s_joints(either):
    """The joint-space DiffIK peer's null-space velocity moves the tool
    by V_n^0's arm twist, k_n grad_x C_m (J_a z = that twist, at least
    norm: z in the row space of J_a), and it answers in the arm's n
    joints and the base's 3; on the 7-joint arm, whose base has no
    flexible mount to hold by bounds, Drake's QP is the least-norm
    problem's answer (an independent KKT system) to 1e-9."""
    arm = either
    n = arm.num_joints
    problems = race.make_problems(6, seed=5, arm=arm)
    peer = race.PlantDiffIk(arm)
    for problem in problems:
        J_a = arm.evaluate(problem.arm_position).J_a
        z = problem.joint_null_velocity
        assert z.shape == (n,)
        np.testing.assert_allclose(
            J_a @ z, problem.null_space_gain * problem.capability_gradient,
            atol=1e-12)
        _, residual, _, _ = np.linalg.lstsq(J_a.T, z, rcond=None)
        assert residual.size == 0 or residual[0] < 1e-20  # z = J_a^T y
        assert peer(problem).shape == (n + 3,)
    if arm.model.passive_joints:
        return
    for problem in problems:
        # min |v - z|^2 s.t. J v = V in the joint space (arm, base in T_w),
        # by its KKT system, then the base's part turned into T_b.
        peer(problem)
        from pydrake.multibody.tree import JacobianWrtVariable

        world = peer.plant.world_frame()
        J = peer.plant.CalcJacobianSpatialVelocity(
            peer.context, JacobianWrtVariable.kV, peer.frame, np.zeros(3),
            world, world)[:, np.concatenate([peer.iv_arm, peer.iv_base])]
        twist = peer._world_twist(problem)
        z = np.concatenate([problem.joint_null_velocity, np.zeros(3)])
        kkt = np.block([[np.eye(n + 3), J.T], [J, np.zeros((6, 6))]])
        v = np.linalg.solve(kkt, np.concatenate([z, twist]))[:n + 3]
        c, s = np.cos(problem.base_yaw), np.sin(problem.base_yaw)
        expected = np.concatenate([v[:n], [c * v[n] + s * v[n + 1],
                                           -s * v[n] + c * v[n + 1],
                                           v[n + 2]]])
        np.testing.assert_allclose(peer(problem), expected, atol=1e-9)
        np.testing.assert_allclose(peer.least_norm(problem), expected,
                                   atol=1e-9)


def test_a_short_tick_on_the_7_joint_robot(lbr):
    """The ticker on the second shipped robot: its controller (seven
    joints in, seven commands out, within its limits), one update a tick,
    the arm measured about its home, every obstacle point outside its
    footprint (1.0 x 0.7 m, not the shipped 0.8 x 0.6 m), a quarter of
    them 0.05 to 0.4 m outside the circle through its corners and the
    rest 0.5 to 4.5 m."""
    from drake_wbc.bench.control_tick import ControllerTicker

    ticker = ControllerTicker(lbr, num_points=40, measurement_sets=6)
    assert ticker.controller.arm is lbr
    half_sizes = load_robot_description(LBR_FILE).base.footprint_half_sizes
    for values in ticker.values:
        q = values["arm.position_measured"]
        assert q.shape == (7,)
        assert np.max(np.abs(q - lbr.home)) <= 0.02
        points = values["lidar.obstacle_points"].get_value()
        gaps = np.hypot(np.maximum(np.abs(points[:, 0]) - half_sizes[0], 0),
                        np.maximum(np.abs(points[:, 1]) - half_sizes[1], 0))
        assert np.all(gaps > 0.0)
        beyond = np.linalg.norm(points, axis=1) - np.hypot(*half_sizes)
        near = len(points) // 4
        assert np.all((beyond[:near] > 0.05) & (beyond[:near] < 0.4))
        assert np.all((beyond[near:] > 0.5) & (beyond[near:] < 4.5))
    simulator = ticker.simulator
    batch = ticker.ticks(5)
    before = simulator.get_num_discrete_updates()
    batch()
    assert simulator.get_num_discrete_updates() - before == 5
    command = ticker.controller.diagram.GetOutputPort(
        "arm.position_command").Eval(ticker.context)
    assert command.shape == (7,)
    assert np.all(command >= lbr.lower) and np.all(command <= lbr.upper)
    assert ticker.controller.safety_reason(ticker.context) == ""


@pytest.mark.filterwarnings("ignore:The default value of raise_error")
@pytest.mark.parametrize("path, name, joints", [(LBR_FILE, "lbr_omni", 7),
                                                (UR_FILE, "ur_omni", 6)],
                         ids=["lbr_omni", "ur_omni"])
def test_quick_bench_on_the_other_shipped_robots(tmp_path, path, name,
                                                 joints):
    """`drake-wbc bench --quick --robot models/lbr_omni.robot.yaml` (and
    ur_omni), at the smallest counts its options allow: every part on
    that robot (the race fair, the joint-space peer answering its own
    problem, the tick, the scenario run on it)."""
    parser = argparse.ArgumentParser()
    add_bench_arguments(parser)
    args = parser.parse_args(["--quick", "--output", str(tmp_path),
                              "--repeats", "1", "--scenario-duration",
                              "0.1", "--robot", str(path)])
    assert run_bench(args, echo=lambda line: None) == 0
    results = json.loads((tmp_path / "bench.json").read_text())
    assert results["robot"] == {"name": name, "arm_joints": joints}
    assert results["settings"]["robot"] == str(path.resolve())
    race_results = results["distribution"]
    assert race_results["fair"]
    for solver, entry in race_results["solve"].items():
        assert entry["max_abs_difference"] <= FAIRNESS_TOLERANCE, solver
    plant = race_results["with_kinematics"]["drake_diffik_plant"]
    assert plant["max_abs_difference"] < 1e-9  # no mount: no bounds
    assert results["control_tick"]["tick"]["time_us"]["median"] > 0
    run = results["scenarios"]["trajectory_tracking"]
    assert run["runs"][0]["robot"] == name
    assert run["runs"][0]["simulated_s"] == pytest.approx(0.1)
    assert f"Robot: {name} ({joints} arm joints)." in (
        tmp_path / "bench.md").read_text()


def test_a_scenario_that_does_not_fit_the_robot_is_skipped(tmp_path):
    """A post 0.7 m ahead of the base's centre (radius 0.25 m) is clear
    of the shipped base (its front at 0.4 m) and overlaps the 7-joint
    robot's (at 0.5 m): on that robot the scenario is skipped, with the
    reason, and the table says so; the goals leave it out."""
    from drake_wbc.bench import report, timing
    from drake_wbc.bench.commands import bench_scenarios
    from drake_wbc.experiments.scenario import find_scenario, load_scenario

    text = find_scenario("trajectory_tracking").read_text()
    path = tmp_path / "post_ahead.yaml"
    path.write_text(text + "\nscene:\n  cylinders:\n  - {name: post, "
                    "position: [0.7, 0.0], radius: 0.25, height: 1.0}\n")
    load_scenario(path)  # checked on the shipped robot: it fits
    settings = dict(scenarios=(str(path),), scenario_duration=0.05,
                    scenario_repeats=2, robot=str(LBR_FILE))
    printed = []
    scenarios = bench_scenarios(settings, echo=printed.append)
    assert set(scenarios) == {"post_ahead"}
    reason = scenarios["post_ahead"]["skipped"]
    assert "post" in reason and "footprint" in reason
    assert sum("skipped" in line for line in printed) == 1  # tried once
    results = {"environment": timing.environment(), "settings": {},
               "scenarios": scenarios,
               "goals": report.evaluate_goals({"scenarios": scenarios})}
    goal = next(g for g in results["goals"]
                if g["goal"] == "scenario_real_time_factor")
    assert goal["measured"] is None and goal["met"] is None
    rows = [line for line in report.markdown(results).splitlines()
            if line.startswith("| post_ahead |")]
    assert len(rows) == 1 and "skipped: " in rows[0]


@pytest.mark.parametrize("argv, message", [
    (["--seed", "-1"], "--seed = -1 is not allowed: must be 0 or greater"),
    (["--repeats", "0"], "--repeats = 0 is not allowed: must be 1 or "
     "greater"),
    # These ran for days (a million repetitions of a bench whose 30 take
    # half a minute).
    (["--repeats", "1000000"], "--repeats = 1000000 is not allowed: must "
     "be at most 1000 (some 20 minutes on a 2-core machine)"),
    (["--scenario-repeats", "101"], "--scenario-repeats = 101 is not "
     "allowed: must be at most 100 (some 40 minutes on a 2-core machine)")])
def test_bad_options_are_named_before_the_bench_starts(argv, message,
                                                       tmp_path, capsys):
    """A negative --seed started the race and then failed with numpy's
    'expected non-negative integer'."""
    from drake_wbc.cli.main import main

    assert main(["bench", "--quick", "--output", str(tmp_path), *argv]) == 2
    out, err = capsys.readouterr()
    assert err == f"drake-wbc bench: {message}\n" and out == ""
