"""drake-wbc bench: the quick run writes well-formed tables, and the race
is fair (every same-problem contender returns the same V_wb)."""

import argparse
import json

import numpy as np
import pytest

from drake_wbc.bench import add_bench_arguments, run_bench
from drake_wbc.bench import distribution_race as race
from drake_wbc.bench.report import GOALS
from drake_wbc.math import distribution, kinematics
from drake_wbc.robot.model import ArmKinematics


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def test_quick_bench_writes_well_formed_tables(tmp_path):
    parser = argparse.ArgumentParser()
    add_bench_arguments(parser)
    args = parser.parse_args(["--quick", "--output", str(tmp_path),
                              "--repeats", "2"])
    printed = []
    assert run_bench(args, echo=printed.append) == 0
    results = json.loads((tmp_path / "bench.json").read_text())
    assert set(results) == {"environment", "settings", "distribution",
                            "control_tick", "scaling", "scenarios", "goals"}
    env = results["environment"]
    assert env["packages"]["drake"] and env["packages"]["numpy"]
    assert env["cpu_count"] >= 1 and env["cpu_model"] and env["python"]
    contenders = results["distribution"]["contenders"]
    assert {"closed_form", "drake_diffik", "qpsolvers_osqp",
            "qpsolvers_clarabel"} <= set(contenders)
    for entry in contenders.values():
        stats = entry["time_us"]
        assert stats["n"] == 2
        assert 0 < stats["p10"] <= stats["median"] <= stats["p90"]
    tick = results["control_tick"]
    assert tick["tick_us"]["median"] > 0
    assert tick["framework_floor_us"]["median"] > 0
    assert set(tick["stages"]) >= {"capability", "distributor",
                                   "base_cdmp", "arm_controller"}
    assert [e["points"] for e in results["scaling"]["obstacle_points"]] \
        == [100, 2000]
    assert [e["rate_hz"] for e in results["scaling"]["control_rate"]] \
        == [100.0, 1000.0]
    run = results["scenarios"]["trajectory_tracking"]
    assert run["real_time_factor"] > 0 and run["peak_memory_mib"] > 50
    assert [g["goal"] for g in results["goals"]] == [g[0] for g in GOALS]
    assert all(isinstance(g["met"], bool) for g in results["goals"])

    text = (tmp_path / "bench.md").read_text()
    assert text in printed
    tables = [line for line in text.splitlines() if line.startswith("|")]
    for name in contenders:
        assert any(line.startswith(f"| {name} |") for line in tables), name
    assert any(line.startswith("| stage capability |") for line in tables)
    assert any(line.startswith("| trajectory_tracking |")
               for line in tables)
    tick_goal = next(line for line in tables
                     if line.startswith("| a full control tick"))
    median = tick["tick_us"]["median"]
    assert f"| {median:.0f} us (median) |" in tick_goal
    # Every table's rows have as many cells as its header.
    blocks, block = [], []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            block.append(line)
        elif block:
            blocks.append(block)
            block = []
    assert len(blocks) == 5
    for rows in blocks:
        assert len({row.count("|") for row in rows}) == 1, rows[0]


@pytest.mark.filterwarnings("ignore:The default value of raise_error")
def test_contenders_agree_without_active_constraints(arm):
    problems = race.make_problems(12, seed=7, arm=arm)
    same, informative = race.make_contenders(arm)
    report = race.fairness(problems, same, informative)
    assert set(report) == set(same) | set(informative)
    for name in same:
        assert report[name]["max_abs_difference"] < 1e-6, name
    # The closed form itself satisfies the task: J_wb V_wb = V_ee.
    solve = same[race.REFERENCE]
    for problem in problems:
        p_ee = arm.evaluate(problem.arm_position).p_ee_in_base
        J = kinematics.whole_body_jacobian(None, p_ee, arm.R_ba)
        np.testing.assert_allclose(J @ solve(problem),
                                   problem.end_effector_velocity,
                                   atol=1e-12)


@pytest.mark.filterwarnings("ignore:The default value of raise_error")
def test_scaled_diffik_is_the_weighted_least_norm_problem(arm):
    """Independent of the controller's code: the weighted problem's KKT
    system, solved directly, gives what every contender gives."""
    problem = race.make_problems(1, seed=3, arm=arm)[0]
    p_ee = arm.evaluate(problem.arm_position).p_ee_in_base
    J = kinematics.whole_body_jacobian(None, p_ee, arm.R_ba)
    W = np.diag(1.0 / np.diag(distribution.weighting_matrix(
        problem.sigma_xy, problem.sigma_phi)))
    V_n = np.concatenate([problem.null_space_gain
                          * problem.capability_gradient, np.zeros(3)])
    kkt = np.block([[W, J.T], [J, np.zeros((6, 6))]])
    rhs = np.concatenate([W @ V_n, problem.end_effector_velocity])
    expected = np.linalg.solve(kkt, rhs)[:9]
    same, _ = race.make_contenders(arm)
    for name, solve in same.items():
        np.testing.assert_allclose(solve(problem), expected, atol=1e-7,
                                   err_msg=name)


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
