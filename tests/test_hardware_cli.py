"""`drake-wbc robot-sim` and `deploy` check their arguments before they
touch LCM: a real-time rate must be a positive finite number (with 0 the
Simulator ran unpaced, and the joints moved at 2 rad/s of wall time)."""

import warnings

import pytest
from omni_arm import write_omni_arm

from drake_wbc.cli.main import main
from drake_wbc.deployment.deploy import deploy
from drake_wbc.experiments.scenario import find_scenario, load_scenario
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.tuning import RobotTuningWarning


@pytest.mark.parametrize("program", ["robot-sim", "deploy"])
@pytest.mark.parametrize("rate", ["0", "-1", "nan", "inf"])
def test_the_realtime_rate_must_be_positive_and_finite(program, rate,
                                                        capsys):
    assert main([program, "hardware", "--realtime-rate", rate]) == 2
    error = capsys.readouterr().err
    assert f"--realtime-rate = {float(rate)!r} is not allowed" in error
    assert "positive finite number" in error


def test_deploy_checks_its_rate_too():
    scenario = load_scenario(find_scenario("hardware"))
    with pytest.raises(ValueError, match="realtime_rate = 0.0 is not "
                                         "allowed"):
        deploy(scenario, realtime_rate=0.0)


@pytest.mark.parametrize("program, longest", [
    ("robot-sim", "3600 s (an hour); leave --duration out to run until "
                  "Ctrl-C"),
    ("deploy", "86400 s (a day)")])
def test_a_duration_beyond_the_longest_is_refused(program, longest, capsys):
    """`--duration 1e300` ran (or waited) for ever without a word."""
    assert main([program, "hardware", "--duration", "1e300"]) == 2
    assert capsys.readouterr().err == (
        f"drake-wbc {program}: --duration = 1e+300 is not allowed: must be "
        f"at most {longest}\n")


def test_a_deployment_may_last_a_working_day(tmp_path, capsys):
    """A deployment keeps no log of its own (its diagnostics go out over
    LCM), so it is not held to a simulated run's hour: a shift of eight
    hours was refused. Here it is taken and waits for the robot, which
    does not answer (LCM in memory, memq://)."""
    path = tmp_path / "scenario.yaml"
    text = find_scenario("hardware").read_text()
    assert "  startup_timeout: 10.0 " in text
    path.write_text(text.replace("  startup_timeout: 10.0 ",
                                 "  startup_timeout: 0.2 "))
    assert main(["deploy", str(path), "--duration", "28800",
                 "--lcm-url", "memq://"]) == 1
    assert "no status" in capsys.readouterr().err
    with pytest.raises(ValueError, match=r"duration = 1e\+300 is not "
                                         r"allowed: must be at most 86400"):
        deploy(load_scenario(find_scenario("hardware")), duration=1e300)


def test_only_the_simulated_robot_starts_at_the_other_robots_home(
        tmp_path, capsys):
    """With --robot another robot's description, robot-sim (the simulated
    robot) starts the arm at that robot's home and says so; deploy starts
    the controller from the measured arm, and said the same, untrue
    there. Here deploy waits for a robot that does not answer (memq://),
    and robot-sim runs 0.05 s on it."""
    robot = write_omni_arm(tmp_path, 7)
    home = list(load_robot_description(robot).arm.home)
    path = tmp_path / "scenario.yaml"
    text = find_scenario("hardware").read_text()
    path.write_text(text.replace("  startup_timeout: 10.0 ",
                                 "  startup_timeout: 0.2 "))
    said = f"the arm starts at omni_arm's home {home}"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RobotTuningWarning)
        assert main(["deploy", str(path), "--robot", str(robot),
                     "--lcm-url", "memq://"]) == 1
        out, err = capsys.readouterr()
        assert "no status" in err
        assert "starts at" not in out and "waiting for" in out
        assert main(["robot-sim", str(path), "--robot", str(robot),
                     "--duration", "0.05", "--lcm-url", "memq://"]) == 0
    assert said in capsys.readouterr().out


def test_robot_sim_shows_a_progress_line(capsys):
    """robot-sim said nothing from its first line to its last: it now
    shows the simulated time, the real-time factor and the time left
    (over LCM in memory, memq://, which nothing else hears)."""
    assert main(["robot-sim", "hardware", "--duration", "0.3",
                 "--lcm-url", "memq://", "--realtime-rate", "3"]) == 0
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines()
             if line.startswith("robot-sim hardware: [")]
    assert len(lines) >= 3, err
    assert " / 0.30 s simulated, real-time factor " in lines[0]
    assert lines[0].endswith(" left") and "about " in lines[0]
    assert lines[-1].startswith("robot-sim hardware: [####################"
                                "####]   0.30 / 0.30 s simulated")
    assert " took " in lines[-1]
    assert out.splitlines()[-1].startswith("robot-sim: 0.30 s simulated in ")


@pytest.mark.parametrize("program", ["robot-sim", "deploy"])
def test_a_bad_lcm_url_is_named_as_typed(program, capsys):
    """It was named lcm_url, the scenario file's field, not the option."""
    assert main([program, "hardware", "--lcm-url", "bogus://x"]) == 2
    assert capsys.readouterr().err == (
        f"drake-wbc {program}: --lcm-url = 'bogus://x' is not allowed: must "
        "start with one of udpm://, memq://, file://\n")
