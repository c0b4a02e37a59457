"""The randomised stress run (drake_wbc.stress.run): its cases are valid,
differ between seeds, and give the same records whoever runs them (this
process, spawned worker processes, a Dask cluster); a broken invariant
makes the exit code non-zero."""

import argparse
import json
import math

import pytest

from drake_wbc.experiments.scenario import Scenario
from drake_wbc.math.validation import validate
from drake_wbc.stress import run as stress
from drake_wbc.stress.cases import random_scenario, violations

SEED = 11
CASES = 2
DURATION = 1.0


@pytest.fixture(scope="module")
def serial():
    """The records of the cases, run one after the other here."""
    return stress.run_cases(SEED, CASES, DURATION, workers=1)


def comparable(records):
    return [stress.comparable(record) for record in records]


def test_the_cases_are_valid_scenarios_that_differ_between_seeds():
    for seed in (0, 1):
        for index in range(4):
            scenario = random_scenario(seed, index, DURATION)
            assert isinstance(scenario, Scenario)
            validate(scenario)
            assert scenario.duration == DURATION
    # repr, as some parameters (holding arrays) do not compare with ==.
    first = [repr(random_scenario(0, i, DURATION)) for i in range(3)]
    again = [repr(random_scenario(0, i, DURATION)) for i in range(3)]
    other = [repr(random_scenario(1, i, DURATION)) for i in range(3)]
    assert first == again
    assert first != other
    assert first[0] != first[1]


def test_the_generated_obstacles_leave_the_way_free():
    """Static obstacles keep CLEARANCE from the footprint's disc at the
    start (the way itself is checked by construction)."""
    from drake_wbc.robot.description import shipped_robot
    from drake_wbc.stress.cases import CLEARANCE, footprint_radius

    FOOTPRINT_RADIUS = footprint_radius(shipped_robot().base)  # noqa: N806

    for index in range(20):
        scene = random_scenario(5, index, 4.0).scene
        for cylinder in scene.cylinders:
            assert math.hypot(*cylinder.position) >= (
                FOOTPRINT_RADIUS + CLEARANCE + cylinder.radius - 1e-12)
        for box in scene.boxes:
            half_diagonal = 0.5 * math.hypot(*box.size[:2])
            assert math.hypot(*box.center[:2]) >= (
                FOOTPRINT_RADIUS + CLEARANCE + half_diagonal - 1e-12)


def test_serial_records_are_complete(serial):
    assert [r["case"] for r in serial] == list(range(CASES))
    for record in serial:
        assert record["error"] == ""
        assert record["duration_s"] == pytest.approx(DURATION)
        assert record["seed"] == SEED


def test_worker_processes_give_the_same_records(serial):
    done = []
    records = stress.run_cases(SEED, CASES, DURATION, workers=2,
                               on_done=done.append)
    assert len(done) == CASES
    assert comparable(records) == comparable(serial)


def test_a_dask_cluster_gives_the_same_records(serial):
    distributed = pytest.importorskip("dask.distributed")
    cluster = distributed.LocalCluster(
        processes=True, n_workers=2, threads_per_worker=1,
        dashboard_address=None)
    try:
        records = stress.run_cases(SEED, CASES, DURATION,
                                   scheduler=cluster.scheduler_address)
    finally:
        cluster.close()
    assert comparable(records) == comparable(serial)


@pytest.mark.parametrize("key, value, fragment", [
    ("all_finite", False, "NaN"),
    ("min_capability", math.nan, "min_capability"),
    ("max_base_command_ratio", 1.5, "base's velocity limit"),
    ("max_filter_state_ratio", 37.0, "wind-up"),
    ("max_joint_speed_command_ratio", 1.01, "velocity limit"),
    ("min_command_joint_limit_margin_rad", -0.01, "beyond a joint limit"),
    ("min_static_obstacle_distance_m", 0.0, "touched a static obstacle"),
    ("error", "RuntimeError: boom", "simulation failed"),
])
def test_an_injected_violation_makes_the_exit_code_non_zero(
        serial, key, value, fragment):
    sound = [dict(record) for record in serial]
    sound[0].update(max_base_command_ratio=0.5, max_filter_state_ratio=0.5,
                    max_joint_speed_command_ratio=0.5,
                    min_command_joint_limit_margin_rad=0.1,
                    min_static_obstacle_distance_m=None)
    for record in sound[1:]:
        record.update(sound[0], case=record["case"])
    assert stress.exit_code(sound) == 0
    broken = [dict(record) for record in sound]
    broken[1][key] = value
    found = violations(broken[1])
    assert any(fragment in line for line in found), found
    assert stress.exit_code(broken) == 1


def test_run_stress_writes_the_results_and_returns_the_exit_code(
        tmp_path, capsys):
    parser = argparse.ArgumentParser()
    stress.add_stress_arguments(parser)
    args = parser.parse_args(["--cases", "1", "--seed", str(SEED),
                              "--workers", "1", "--duration", "0.3",
                              "--output", str(tmp_path)])
    code = stress.run_stress(args)
    output = capsys.readouterr()
    document = json.loads((tmp_path / "stress.json").read_text())
    assert document["seed"] == SEED
    assert len(document["cases"]) == 1
    assert code == (1 if document["cases"][0]["violations"] else 0)
    assert code == document["failed"]
    assert "1 / 1 cases done" in output.err
    assert "invariants" in output.out
    header = (tmp_path / "stress.csv").read_text().splitlines()[0]
    assert "min_static_obstacle_distance_m" in header


@pytest.mark.parametrize("overrides, fragment", [
    (dict(cases=0), "cases = 0"),
    (dict(seed=-1), "seed = -1"),
    (dict(duration=0.0), "duration = 0.0"),
    (dict(workers=0), "workers = 0"),
])
def test_bad_arguments_are_named(overrides, fragment):
    arguments = dict(seed=0, cases=1, duration=1.0, workers=1)
    arguments.update(overrides)
    with pytest.raises(ValueError, match=fragment):
        stress.run_cases(**arguments)


def _stress_arguments(tmp_path, *extra):
    parser = argparse.ArgumentParser()
    stress.add_stress_arguments(parser)
    return parser.parse_args(["--seed", str(SEED), "--workers", "1",
                              "--duration", "0.3", "--output",
                              str(tmp_path), *extra])


def test_the_journal_keeps_each_case_and_resume_runs_only_the_rest(
        tmp_path, capsys):
    stress.run_stress(_stress_arguments(tmp_path, "--cases", "1"))
    lines = (tmp_path / "stress.jsonl").read_text().splitlines()
    assert json.loads(lines[0])["settings"]["seed"] == SEED
    first = json.loads(lines[1])
    assert first["case"] == 0
    capsys.readouterr()
    # A line cut short by a stopped run is ignored on resume.
    with (tmp_path / "stress.jsonl").open("a") as stream:
        stream.write('{"case": 1, "seed"')
    stress.run_stress(_stress_arguments(tmp_path, "--cases", "2",
                                        "--resume"))
    output = capsys.readouterr()
    assert "1 case(s) kept" in output.out
    # --workers 1 runs the cases here, as its help says, and so the
    # command says (it said "in 1 worker process(es)").
    assert f"seed {SEED}, in this process;" in output.out
    assert "1 / 1 cases done" in output.err
    document = json.loads((tmp_path / "stress.json").read_text())
    assert [case["case"] for case in document["cases"]] == [0, 1]
    assert stress.comparable(document["cases"][0]) == stress.comparable(
        dict(first, violations=document["cases"][0]["violations"]))
    fresh = stress.run_cases(SEED, 2, 0.3, workers=1)
    assert stress.comparable(document["cases"][1]) == stress.comparable(
        dict(fresh[1], violations=violations(fresh[1])))


def test_resume_refuses_a_journal_of_another_seed(tmp_path):
    stress.Journal(tmp_path, dict(seed=SEED + 1, duration_s=0.3))
    with pytest.raises(ValueError, match="--resume is not allowed"):
        stress.run_stress(_stress_arguments(tmp_path, "--cases", "1",
                                            "--resume"))


def test_a_long_run_summarises_the_spread_and_lists_the_failures(serial):
    records = [dict(serial[i % CASES], case=i)
               for i in range(stress.SUMMARY_ROWS + 5)]
    records[7]["max_base_command_ratio"] = 2.0
    text = stress.summary_table(records)
    assert "least" in text and "median" in text
    assert "1 failing case(s):" in text
    failing_rows = [line for line in text.splitlines()
                    if "base's velocity limit" in line]
    assert len(failing_rows) == 1 and failing_rows[0].split()[0] == "7"
    assert len(text.splitlines()) < len(records)


@pytest.mark.parametrize("bad, fragment", [
    (("--cases", "0"), "^--cases = 0 is not allowed: must be 1 or greater$"),
    (("--cases", "1", "--workers", "0"),
     "^--workers = 0 is not allowed: must be 1 or greater$"),
    (("--cases", "1", "--duration", "0"),
     r"^--duration = 0\.0 is not allowed: must be > 0 s$"),
    (("--cases", "1", "--seed", "-1"),
     "^--seed = -1 is not allowed: must be 0 or greater$"),
    (("--cases", "1", "--scheduler", "10.0.0.5"),
     "^--scheduler = '10.0.0.5' is not allowed: missing port number in "
     "address '10.0.0.5' .must be a Dask scheduler's address, e.g. "
     "tcp://10.0.0.5:8786.$"),
])
def test_bad_arguments_leave_the_journal_untouched(tmp_path, bad, fragment):
    """A mistyped --cases 0 wiped the previous run's journal before the
    arguments were checked. The error names the option as it is typed,
    a whole number as an integer."""
    journal = stress.Journal(tmp_path, dict(seed=SEED, duration_s=0.3))
    journal.append(dict(case=0, seed=SEED, error=""))
    before = journal.path.read_bytes()
    parser = argparse.ArgumentParser()
    stress.add_stress_arguments(parser)
    args = parser.parse_args(["--seed", str(SEED), "--duration", "0.3",
                              "--output", str(tmp_path), *bad])
    with pytest.raises(ValueError, match=fragment):
        stress.run_stress(args)
    assert journal.path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stress.jsonl"]


def test_resume_reports_and_skips_damaged_journal_lines(tmp_path):
    """A damaged line crashed --resume (only a line cut short was
    skipped, silently)."""
    settings = dict(seed=SEED, duration_s=0.3)
    journal = stress.Journal(tmp_path, settings)
    journal.append(dict(case=0, seed=SEED, error="", min_capability=0.05))
    with journal.path.open("a") as stream:
        stream.write("[1, 2]\n")                      # JSON, not a record
        stream.write('{"seed": 11}\n')                # no case number
        stream.write('{"case": "two"}\n')             # not a number
        stream.write('{"case": -1}\n')
        stream.write("\x00\x00garbage\n")             # not JSON
    with journal.path.open("ab") as stream:
        stream.write(b'{"case": 3, "note": "caf\xe9"}\n')  # kept, as caf?
        stream.write(b'{"case": 2, "seed": 11, "error": ""}\n')
        stream.write(b'{"case": 4, "seed"')            # cut short
    reported = []
    resumed = stress.Journal(tmp_path, settings, resume=True,
                             report=reported.append)
    assert [r["case"] for r in resumed.records] == [0, 2, 3]
    assert len(reported) == 6
    for number, line in zip((3, 4, 5, 6, 7, 10), reported, strict=True):
        assert f"stress.jsonl line {number} is not a record" in line
        assert "skipped" in line
    lines = resumed.path.read_text().splitlines()
    assert [json.loads(line).get("case") for line in lines] == [
        None, 0, 2, 3]


def test_resume_refuses_a_journal_whose_settings_are_damaged(tmp_path):
    (tmp_path / "stress.jsonl").write_text('{"settings": [}\n{"case": 0}\n')
    with pytest.raises(ValueError, match="first line.*is not the settings"):
        stress.run_stress(_stress_arguments(tmp_path, "--cases", "1",
                                            "--resume"))
    assert "settings\": [}" in (tmp_path / "stress.jsonl").read_text()


def test_the_cases_run_on_another_robot(tmp_path):
    """`stress --robot`: on the second shipped robot (a 7-joint arm on a
    1.0 x 0.7 m base) the arm starts near its home, the obstacles keep
    clear of its larger footprint, and a case runs within that robot's
    own limits."""
    from drake_wbc.robot.description import load_robot_description, models_dir
    from drake_wbc.stress.cases import CLEARANCE, footprint_radius, run_case

    lbr = str(models_dir() / "lbr_omni.robot.yaml")
    description = load_robot_description(lbr)
    reach = footprint_radius(description.base) + CLEARANCE
    for index in range(6):
        scenario = random_scenario(3, index, 1.0, robot=lbr)
        assert scenario.robot == lbr
        start = scenario.station.initial_arm_positions
        assert len(start) == 7
        assert max(abs(q - h) for q, h in zip(start, description.arm.home,
                                              strict=True)) <= 0.15
        for cylinder in scenario.scene.cylinders:
            assert math.hypot(*cylinder.position) >= (
                reach + cylinder.radius - 1e-12)
    record = run_case(3, 0, 0.3, lbr)
    assert not record.get("error") and violations(record) == []


def test_the_base_command_is_checked_against_that_robots_own_limits():
    """On the second shipped robot (its base's own 0.8 m/s, the shipped
    robot's 1 m/s) a base command of 0.9 m/s breaks the invariant: its
    ratio is taken to the robot's own limit."""
    import numpy as np

    from drake_wbc.controller.run_log import RunLog
    from drake_wbc.experiments.runner import build_closed_loop, simulate
    from drake_wbc.robot.description import load_robot_description, models_dir
    from drake_wbc.stress.cases import case_record

    lbr = str(models_dir() / "lbr_omni.robot.yaml")
    own = load_robot_description(lbr).base.velocity_limits
    scenario = random_scenario(3, 0, 0.1, robot=lbr)
    log = simulate(build_closed_loop(scenario))
    signals = dict(log.signals)
    command = np.zeros_like(signals["base.velocity_command"])
    command[:, 0] = 0.9
    signals["base.velocity_command"] = command
    record = case_record(3, 0, scenario, RunLog(log.time, signals,
                                                log.columns))
    assert record["max_base_command_ratio"] == pytest.approx(0.9 / own[0])
    assert any("base velocity command" in v for v in violations(record))


def _raising(error):
    def metric(*args, **kwargs):
        raise error
    return metric


def test_any_exception_of_a_case_is_recorded_and_the_run_goes_on(
        tmp_path, capsys, monkeypatch):
    """An IndexError in measuring a case (injected into its obstacle
    distance) ended `drake-wbc stress` with a traceback, the case
    unrecorded: it is the case's error, a broken invariant, and the run
    writes its results and exits 1."""
    from drake_wbc.stress import cases

    monkeypatch.setattr(cases, "static_distances", _raising(
        IndexError("index 3 is out of bounds for axis 0 with size 3")))
    code = stress.run_stress(_stress_arguments(tmp_path, "--cases", "1"))
    assert code == 1
    (record,) = json.loads((tmp_path / "stress.json").read_text())["cases"]
    assert record["error"] == ("IndexError: index 3 is out of bounds for "
                               "axis 0 with size 3")
    assert "the simulation failed: IndexError" in capsys.readouterr().out


def test_a_case_that_cannot_be_drawn_is_recorded():
    """The case's scenario is drawn within the case: an error there is
    the case's record, not an error of the run (it reached the command
    as a usage error, exit 2)."""
    from drake_wbc.stress.cases import run_case

    record = run_case(SEED, 0, 0.3, robot="/nonexistent/arm.robot.yaml")
    assert record["error"].startswith("FileNotFoundError: ")
    assert violations(record) == [
        f"the simulation failed: {record['error']}"]


@pytest.mark.parametrize("cause", [False, True])
def test_a_stop_within_a_case_is_not_recorded_but_stops_the_run(
        monkeypatch, cause):
    """A signal's Stopped passes a case, and so does an exception it
    caused (compiled code turns it into a SystemError)."""
    import signal

    from drake_wbc.stress import cases

    stop = stress.Stopped(signal.SIGINT)
    if cause:
        error = SystemError("error return without exception set")
        error.__cause__ = stop
    else:
        error = stop
    monkeypatch.setattr(cases, "static_distances", _raising(error))
    with pytest.raises(type(error)):
        cases.run_case(SEED, 0, 0.3)


def test_case_runs_one_case_alone_as_the_whole_run_does(serial, tmp_path,
                                                        capsys):
    """`--case K` runs case K of the seed alone, into <output>/case_K/,
    its record that of the same case in a run of them all."""
    code = stress.run_stress(_stress_arguments(
        tmp_path, "--case", "1", "--duration", str(DURATION)))
    document = json.loads((tmp_path / "case_1" / "stress.json").read_text())
    (record,) = document["cases"]
    assert stress.comparable(record) == stress.comparable(
        dict(serial[1], violations=violations(serial[1])))
    assert code == (1 if violations(serial[1]) else 0)
    assert not (tmp_path / "stress.json").exists()
    assert "case 1 of 1.0 s, seed 11" in capsys.readouterr().out
    with pytest.raises(ValueError, match=r"^--case = -1 is not allowed"):
        stress.run_stress(_stress_arguments(tmp_path, "--case", "-1"))


def test_a_failing_case_says_how_to_run_it_again(tmp_path, capsys,
                                                 monkeypatch):
    """A failing case's line gives the command that runs it alone, and
    its scenario is written beside stress.json: the command fails the
    same way, and `drake-wbc run` reads the scenario back as the case's
    (a failure said what broke, not how to run it again)."""
    import shlex

    from drake_wbc.cli.main import main
    from drake_wbc.experiments.scenario import load_scenario, scenario_text
    from drake_wbc.stress import cases

    monkeypatch.setattr(cases, "static_distances", _raising(
        IndexError("injected")))
    assert stress.run_stress(_stress_arguments(tmp_path, "--cases",
                                               "2")) == 1
    out = capsys.readouterr().out
    scenario = tmp_path / "case_1.yaml"
    command = (f"drake-wbc stress --seed {SEED} --case 1 --duration 0.3 "
               f"--output {tmp_path}")
    assert (f"case 1: run it alone with {command}; its scenario, for "
            f"drake-wbc run: {scenario}") in out
    assert scenario_text(load_scenario(scenario)) == scenario_text(
        random_scenario(SEED, 1, 0.3))
    assert main(shlex.split(command)[1:]) == 1
    (record,) = json.loads(
        (tmp_path / "case_1" / "stress.json").read_text())["cases"]
    assert (record["case"], record["error"]) == (1, "IndexError: injected")
