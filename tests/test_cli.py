"""The drake-wbc command and its demo."""

import base64
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from omni_arm import write_omni_arm

from drake_wbc.cli.main import main, make_parser
from drake_wbc.math import capability
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics


def test_help_lists_subcommands():
    result = subprocess.run(
        [sys.executable, "-m", "drake_wbc.cli", "--help"],
        capture_output=True, text=True, check=True,
    )
    assert "usage: drake-wbc" in result.stdout
    assert "demo" in result.stdout


def test_no_subcommand_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage: drake-wbc" in capsys.readouterr().out


def test_demo_reports_the_model_and_writes_a_page(tmp_path, capsys):
    assert main(["demo", "--output", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for joint in ("base_x", "base_y", "base_yaw", "mount_roll",
                  "mount_pitch", "joint1", "joint6"):
        assert joint in out
    # The printed C_m is the capability at home, computed independently.
    kinematics = ArmKinematics()
    J_a = kinematics.evaluate(HOME_ARM_POSITIONS).J_a
    C_m = capability.capability(J_a, HOME_ARM_POSITIONS, kinematics.lower,
                                kinematics.upper)
    assert f"C_m = {C_m:.4f}" in out
    # The base's numbers that the controller's safety takes, as described.
    base = kinematics.model.description.base
    assert (f"footprint {2 * base.footprint_half_sizes[0]:.2f} x "
            f"{2 * base.footprint_half_sizes[1]:.2f} m") in out
    assert f"velocity loop lag {base.velocity_lag:g} s" in out
    page = tmp_path / "mcr_model.html"
    html = page.read_text()
    assert html.lstrip().lower().startswith("<!doctype html")
    # Self-contained: the viewer's script and the scene are inline, the
    # scene as base64-encoded commands that name every part of the robot.
    assert "<script" in html and "http://" not in html.split("<body")[0]
    blobs = re.findall(r"data:application/octet-binary;base64,([^\"']+)",
                       html)
    scene = b"".join(base64.b64decode(blob) for blob in blobs)
    for name in (b"elfin5", b"mcr_base", b"ft300_wiping_tool",
                 b"lidar_fields"):
        assert name in scene


def test_demo_of_a_robot_of_ones_own_proposes_its_tuning(tmp_path, capsys):
    path = write_omni_arm(tmp_path, 7)
    assert main(["demo", "--robot", str(path), "--output",
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for joint in ("j1", "j7", "base_yaw"):
        assert joint in out
    assert "caps P_jnt at 0.60 on this arm's 7 joints" in out
    assert "proposed capability_band" in out
    assert (tmp_path / "omni_arm_model.html").is_file()
    path = write_omni_arm(tmp_path, 5, accelerations=False)
    assert main(["demo", "--robot", str(path), "--output",
                 str(tmp_path)]) == 2
    assert "arm.joints" in capsys.readouterr().err


def test_demo_aligns_the_columns_of_long_joint_names(tmp_path, capsys):
    """A vendor's joint names (longer than the shipped robot's 12
    characters) keep the joint table's columns aligned: the kind of
    every joint starts in one column."""
    path = write_omni_arm(tmp_path, 6)
    for file in (path, tmp_path / "omni_arm.urdf"):
        file.write_text(file.read_text().replace(
            "j2", "shoulder_lift_joint"))
    assert main(["demo", "--robot", str(path), "--output",
                 str(tmp_path)]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines()
            if re.match(r"^  (base|arm) ", line)]
    assert any("shoulder_lift_joint" in row for row in rows)
    starts = {re.search(r" (revolute|prismatic) ", row).start()
              for row in rows}
    assert len(rows) == 9 and len(starts) == 1


def test_demo_says_an_arm_joint_without_an_actuator_has_none(tmp_path,
                                                             capsys):
    """An arm joint whose URDF gives it no transmission (no actuator) is
    listed as having none, which the simulated station refuses (it said
    "unactuated (spring-damper)", though the joint has no spring); the
    shipped robot's mount joints, springs, are spring-dampers."""
    from drake_wbc.robot.description import load_robot_description
    from drake_wbc.station.simulation import SimulatedStation

    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    text = urdf.read_text()
    start = text.index("<transmission name='j3_drive'>")
    end = text.index("</transmission>", start) + len("</transmission>")
    urdf.write_text(text[:start] + text[end:])
    assert main(["demo", "--robot", str(path), "--output",
                 str(tmp_path)]) == 0
    rows = {line.split()[1]: line for line in
            capsys.readouterr().out.splitlines()
            if re.match(r"^  (base|mount|arm) ", line)}
    assert rows["j3"].endswith("no actuator (the simulated station "
                               "refuses it)")
    assert rows["j2"].endswith("100 N m")
    assert "spring" not in "".join(rows.values())
    with pytest.raises(ValueError, match="the model gives it no actuator"):
        SimulatedStation(robot=load_robot_description(path))
    assert main(["demo", "--output", str(tmp_path)]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines()
            if re.match(r"^  mount ", line)]
    assert len(rows) == 2
    assert all(row.endswith("unactuated (spring-damper)") for row in rows)


def test_demo_says_where_the_robots_own_bodies_overlap(tmp_path, capsys):
    """Two links of the arm whose collision spheres overlap at home (link1
    and link3, two joints apart), which the simulated station refuses:
    demo says so, naming the pair, the depth the station's error gives
    and what to do; with the README's collision filter group it says
    nothing of it (it said nothing either way)."""
    from omni_arm import SELF_FILTER, add_collision_spheres, use_directives

    from drake_wbc.robot.description import load_robot_description
    from drake_wbc.station.simulation import SimulatedStation

    path = write_omni_arm(tmp_path, 7)
    add_collision_spheres(tmp_path, {"link1": 0.32, "link3": 0.32})
    use_directives(tmp_path, path)
    with pytest.raises(ValueError) as refused:
        SimulatedStation(robot=load_robot_description(path))
    depth = re.search(r"'omni_arm::link3' by ([0-9.]+) mm",
                      str(refused.value)).group(1)
    assert main(["demo", "--robot", str(path), "--output",
                 str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (f"The robot's own bodies overlap at this configuration: "
            f"omni_arm::link1 and omni_arm::link3 by {depth} mm.") in out
    assert "filter their contacts in the model directives" in out
    use_directives(tmp_path, path, SELF_FILTER)
    assert main(["demo", "--robot", str(path), "--output",
                 str(tmp_path)]) == 0
    assert "overlap" not in capsys.readouterr().out


def test_demo_rejects_a_bad_configuration(tmp_path, capsys):
    code = main(["demo", "--output", str(tmp_path), "--q-arm",
                 "0", "0", "nan", "0", "0", "0"])
    assert code == 2
    assert "--q-arm" in capsys.readouterr().err


def test_demo_rejects_a_configuration_outside_the_joint_limits(tmp_path,
                                                               capsys):
    """A joint past its limit is named with its value and limits, not
    reported as a capability of zero."""
    upper = float(ArmKinematics().upper[0])
    assert main(["demo", "--output", str(tmp_path), "--q-arm",
                 "9", "0", "0", "0", "0", "0"]) == 2
    out, err = capsys.readouterr()
    assert err == (
        "drake-wbc demo: --q-arm[0] = 9.0 rad (joint joint1) is not "
        f"allowed: must lie within the joint's limits [{-upper!r}, "
        f"{upper!r}] rad\n")
    assert out == "" and list(tmp_path.iterdir()) == []
    q = ["0"] * 5 + [repr(upper)]  # at a limit: allowed
    assert main(["demo", "--output", str(tmp_path), "--q-arm", *q]) == 0


@pytest.mark.parametrize("q", [np.zeros(6), HOME_ARM_POSITIONS])
def test_demo_at_other_configurations(tmp_path, capsys, q):
    args = ["demo", "--output", str(tmp_path), "--q-arm"]
    assert main(args + [str(x) for x in q]) == 0
    assert "C_m" in capsys.readouterr().out


def test_run_lists_every_scenario(capsys):
    from drake_wbc.experiments.scenario import DEFAULT_SCENARIO, scenario_files

    assert main(["run", "--list"]) == 0
    out = capsys.readouterr().out.splitlines()
    names = [path.stem for path in scenario_files()]
    assert [line.split()[0] for line in out] == names
    # The descriptions start in one column, after the longest name.
    width = max(map(len, names))
    assert all(line[width:width + 2] == "  " and line[width + 2] != " "
               for line in out)
    assert "controller" not in names
    assert sum("(default)" in line for line in out) == (
        DEFAULT_SCENARIO in names)


def test_run_list_refuses_a_scenario_it_would_ignore(capsys):
    """`run --list extra` listed every scenario and exited 0, the name
    ignored."""
    assert main(["run", "--list", "extra"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == (
        "drake-wbc run: scenario = 'extra' is not allowed with --list, "
        "which lists every scenario: give one or the other\n")


def test_the_teach_help_gives_the_default_number_of_basis_functions(
        monkeypatch):
    """--num-basis's help said "(default: 40)", written out, not the
    default that learn_movement takes (the movement module's
    DEFAULT_NUM_BASIS): it follows the constant."""
    import argparse

    from drake_wbc.cli import teach as teach_commands
    from drake_wbc.math import movement as mv

    for number in (mv.DEFAULT_NUM_BASIS, mv.DEFAULT_NUM_BASIS + 1):
        monkeypatch.setattr(mv, "DEFAULT_NUM_BASIS", number)
        parser = argparse.ArgumentParser()
        teach_commands.add_teach_arguments(parser)
        (help_text,) = [action.help for action in parser._actions
                        if action.dest == "num_basis"]
        assert help_text.endswith(f"(default: {number})")


def test_a_closed_pipe_ends_the_command_quietly():
    """`drake-wbc run --list | head -1`: when the reader has gone, the
    command ends with 141 (as a shell's SIGPIPE) and no traceback."""
    process = subprocess.Popen(
        [sys.executable, "-m", "drake_wbc.cli", "run", "--list"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()  # gone before the first line is written
    _, error = process.communicate(timeout=120)
    assert process.returncode == 141, error.decode()
    assert error == b""


def test_run_names_an_unknown_scenario(capsys):
    assert main(["run", "no_such_scenario"]) == 2
    err = capsys.readouterr().err
    assert "no_such_scenario" in err and "trajectory_tracking" in err


def test_run_reports_a_bad_scenario_file(tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text("duration: 5.0\nscene:\n  people:\n"
                    "  - {name: p, radius: -0.2}\n")
    assert main(["run", str(path), "--output", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and "scene.people[0].radius = -0.2" in err


def test_run_writes_logs_figures_replay_and_summary(tmp_path, capsys):
    assert main(["run", "trajectory_tracking", "--duration", "1.2",
                 "--output", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "ratio_unfiltered_to_filtered" in out
    # The last line names every file written.
    written = out.strip().splitlines()[-1]
    assert written.startswith(f"Written to {tmp_path}/: ")
    assert sorted(written.split(": ", 1)[1].split(", ")) == sorted(
        path.name for path in tmp_path.iterdir())
    for name in ("summary.json", "trajectory_tracking.png",
                 "log_filtered.npz", "log_unfiltered.csv",
                 "replay_filtered.html"):
        assert (tmp_path / name).is_file(), name
    header = (tmp_path / "log_filtered.csv").read_text().splitlines()[0]
    assert header.startswith("time,") and "capability.C_m" in header


@pytest.mark.parametrize("argv", [
    ["run", "fixed_point"], ["robot-sim", "hardware"], ["deploy", "hardware"],
    ["teach", "teach"], ["replay", "movement.yaml"], ["bode"], ["diagram"],
    ["demo"], ["stress"]])
def test_every_command_that_runs_a_scenario_takes_a_robot(argv):
    args = make_parser().parse_args(argv + ["--robot", "my_robot.yaml"])
    assert args.robot == Path("my_robot.yaml")


@pytest.mark.parametrize("argv", [
    ["run"], ["run", "--sweep"], ["bode"], ["diagram"], ["stress"],
    ["replay", "movement.yaml"], ["teach", "teach"], ["bench", "--quick"],
    ["deploy", "hardware"], ["robot-sim", "hardware"], ["demo"]])
def test_every_command_names_a_robot_file_that_is_not_there(
        argv, tmp_path, monkeypatch, capsys):
    """A --robot that names no file is refused with the option, its value
    and why, before anything is printed or written."""
    monkeypatch.chdir(tmp_path)
    assert main(argv + ["--robot", "nosuch.yaml"]) == 2
    out, err = capsys.readouterr()
    assert err == (f"drake-wbc {argv[0]}: --robot = 'nosuch.yaml' is not "
                   "allowed: no such file\n")
    assert out == ""
    assert list(tmp_path.iterdir()) == []
    assert main(argv + ["--robot", str(tmp_path)]) == 2
    assert "a folder, not a robot description file" in capsys.readouterr().err


def test_demo_reports_the_capability_with_the_controllers_k_j(tmp_path,
                                                                capsys):
    """The capability line and the tuning's take the k_j the controller
    runs: the description's tuning where the controller gives none, the
    controller's own where --controller gives one."""
    robot = (Path(__file__).resolve().parents[1] / "examples" / "own_robot"
             / "omni_arm.robot.yaml")
    controller = tmp_path / "controller.yaml"
    controller.write_text("capability:\n  joint_limit_gain: 30000\n")
    for extra, k_j in (([], "60000"),
                       (["--controller", str(controller)], "30000")):
        assert main(["demo", "--robot", str(robot), "--output",
                     str(tmp_path)] + extra) == 0
        out = capsys.readouterr().out
        assert f"Capability of movement (k_j = {k_j})" in out
        assert f"with k_j = {k_j} and the band" in out


def test_demo_lists_the_arms_own_limits(tmp_path, capsys):
    """The joint table shows the limits the arm's controller and the LCM
    guard hold it to: the description's where it tightens the model's
    (the UR-class arm's elbow, +-pi of the model's +-2 pi), which the
    table showed as the model's."""
    robot = (Path(__file__).resolve().parents[1] / "models"
             / "ur_omni.robot.yaml")
    assert main(["demo", "--robot", str(robot), "--output",
                 str(tmp_path)]) == 0
    rows = {line.split()[1]: line for line in
            capsys.readouterr().out.splitlines() if line.startswith("  arm ")}
    assert "[-3.14, +3.14] rad" in rows["elbow"]
    for name in ("shoulder_pan", "shoulder_lift", "wrist_1", "wrist_2",
                 "wrist_3"):
        assert "[-6.28, +6.28] rad" in rows[name]
    assert all("3.14 rad/s" in row for row in rows.values())


def test_the_summary_heads_a_single_run_without_its_name():
    """One run's metrics read "Run metrics:" (not "Run run:", the default
    run's name); several runs are each headed by their name."""
    from drake_wbc.experiments.reports import format_summary

    summary = dict(scenario="s", description="d", metrics={},
                   runs={"run": {"m": 1.0}}, files=["log_run.npz"])
    assert "Run metrics:\n  m " in format_summary(summary, Path("out"))
    summary["runs"]["other"] = {"m": 2.0}
    text = format_summary(summary, Path("out"))
    assert "Run run:\n  m " in text and "Run other:\n  m " in text


def test_a_run_shorter_than_the_step_writes_its_files(tmp_path, capsys):
    """`--duration` shorter than the step's start (1 s) leaves the step's
    metrics without samples: they are NaN ("nan" in summary.json), and
    the logs, the figure and the summary are still written."""
    import json

    assert main(["run", "trajectory_tracking", "--duration", "0.5",
                 "--no-replay", "--output", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    metrics = summary["metrics"]
    assert metrics["filtered.error_rms_total_m_s"] == "nan"
    assert metrics["unfiltered.peak_error_after_step_m_s"] == "nan"
    assert (tmp_path / "trajectory_tracking.png").is_file()


@pytest.mark.parametrize("argv", [
    ["run", "--duration", "0.1", "--no-replay"], ["diagram"], ["demo"],
    ["teach", "teach"]])
def test_an_output_that_cannot_be_written_is_named(argv, tmp_path, capsys):
    """An --output under a file is refused in one line naming the option,
    its value and why (it was a traceback from mkdir)."""
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    output = blocker / "out"
    assert main(argv + ["--output", str(output)]) == 2
    err = capsys.readouterr().err
    assert err == (f"drake-wbc {argv[0]}: --output = {str(output)!r} is not "
                   f"allowed: cannot write {str(output)!r} (Not a "
                   "directory)\n")


def test_an_output_whose_folder_is_a_file_is_named(tmp_path, capsys):
    """The folder on the way to --movement is a file: the error names the
    option too, and the exit code is a bad argument's."""
    from drake_wbc.math import movement as mv

    blocker = tmp_path / "a_file"
    blocker.write_text("")
    shipped = mv.LearnedMovement.load(
        Path(__file__).resolve().parents[1] / "diagrams" / "movements"
        / "teach.yaml")
    with pytest.raises(OSError) as error:
        shipped.save(blocker / "movement.yaml")
    from drake_wbc.cli.main import _unwritable

    args = make_parser().parse_args(
        ["teach", "teach", "--movement", str(blocker / "movement.yaml")])
    message, code = _unwritable(args, error.value)
    assert code == 2
    assert message.startswith(
        f"--movement = {str(blocker / 'movement.yaml')!r} is not allowed: "
        f"cannot write {str(blocker)!r}")


def test_demo_names_a_controller_file_that_is_not_there(tmp_path, capsys):
    assert main(["demo", "--controller", str(tmp_path / "nosuch.yaml"),
                 "--output", str(tmp_path)]) == 2
    assert capsys.readouterr().err == (
        f"drake-wbc demo: --controller = {str(tmp_path / 'nosuch.yaml')!r} "
        "is not allowed: no such file\n")


@pytest.mark.parametrize("argv, option", [
    (["plot"], "logfile"), (["teach", "teach", "--log"], "--log")])
def test_a_folder_given_as_an_lcm_log_is_named(argv, option, tmp_path,
                                               capsys):
    """A folder is not 'no such file': the error says what it is."""
    assert main(argv + [str(tmp_path), "--output",
                        str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == (
        f"drake-wbc {argv[0]}: {option} = {str(tmp_path)!r} is not "
        "allowed: a folder, not an LCM log\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("duration, allowed", [
    ("1e300", "must be at most 3600 s (an hour)"),
    ("3600.5", "must be at most 3600 s (an hour)"),
    ("0.001", "must be at least the scenario's outputs.log_period, 0.01 s "
              "(a shorter run logs its start alone)")])
def test_run_refuses_a_duration_it_cannot_run(duration, allowed, tmp_path,
                                              capsys):
    """`run --duration 1e300` ran for ever without a word (its first
    stretch of the Simulator was 5e297 s); 0.001 s ended in numpy's
    'zero-size array' error. Both are refused in one line before
    anything is written."""
    output = tmp_path / "out"
    assert main(["run", "--duration", duration, "--output",
                 str(output)]) == 2
    out, err = capsys.readouterr()
    assert err == (f"drake-wbc run: --duration = {float(duration)!r} is not "
                   f"allowed: {allowed}\n")
    assert out == "" and not output.exists()


def test_a_scenario_file_cannot_last_for_ever(tmp_path, capsys):
    path = tmp_path / "long.yaml"
    path.write_text("duration: 1.0e+300\n")
    assert main(["run", str(path), "--output", str(tmp_path / "o")]) == 2
    assert "duration = 1e+300 is not allowed: must be at most 3600 s" in (
        capsys.readouterr().err)


@pytest.mark.parametrize("argv", [
    ["stress", "--cases", "1"], ["bench", "--quick", "--scenario"]])
def test_every_duration_option_has_the_same_bound(argv, tmp_path, capsys):
    option = "--duration" if argv[0] == "stress" else "--scenario-duration"
    argv = [a for a in argv if a != "--scenario"]
    assert main(argv + [option, "1e300", "--output",
                        str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == (
        f"drake-wbc {argv[0]}: {option} = 1e+300 is not allowed: must be "
        "at most 3600 s (an hour)\n")
    assert not (tmp_path / "o").exists()


def test_a_long_run_shows_its_progress_and_time_left_at_once(tmp_path):
    """The longest run allowed (an hour simulated) says how far it is and
    how long it has left within its first simulated second: the
    Simulator advances at most MAX_CHUNK (1 s) at a time (it was a
    two-hundredth of the run, 18 s here and 5e297 s for 1e300).

    The command runs with Python's own Ctrl-C handler whatever the suite
    was started from: a suite started as a background job of a shell
    inherits SIGINT ignored, and so would the command (it finished its
    hour instead of stopping)."""
    import signal

    process = subprocess.Popen(
        [sys.executable, "-c",
         "import signal, sys; "
         "signal.signal(signal.SIGINT, signal.default_int_handler); "
         "from drake_wbc.cli.main import main; sys.exit(main())",
         "run", "--duration", "3600", "--no-replay", "--output",
         str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stderr.readline()
        assert line.startswith("with base filter: ["), line
        # The first line: the first chunk, at most a second.
        t = float(line.split("]")[1].split("/")[0])
        assert 0.0 < t <= 1.0
        assert "/ 3600.00 s simulated, real-time factor" in line
        assert re.search(r", about (\d+ h \d+ min|\d+ min \d+ s) left$",
                         line.strip()), line
    finally:
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert "Traceback" not in err


def test_the_progress_line_tells_the_time_left_and_ends_once():
    """Off a terminal: a line a tenth of the run with the time left, and
    the last line once, saying how long the run took; a run until Ctrl-C
    (no duration) has neither bar nor time left."""
    import io

    from drake_wbc.experiments.runner import Progress, wall_time_text

    stream = io.StringIO()
    meter = Progress("run", 10.0, stream=stream)
    for t in (1.0, 1.5, 2.0, 10.0):
        meter.update(t)
    meter.update(10.0, done=True)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 3  # 1.0, 2.0 (a tenth later) and 10.0, once
    assert lines[0].startswith("run: [##......................]   1.00 / "
                               "10.00 s simulated, real-time factor ")
    assert lines[0].endswith(" left") and "about " in lines[0]
    assert lines[2].startswith("run: [########################]  10.00")
    stream = io.StringIO()
    meter = Progress("robot-sim", None, stream=stream)
    meter.update(0.05)
    assert stream.getvalue().startswith("robot-sim:     0.05 s simulated, "
                                        "real-time factor ")
    assert stream.getvalue().endswith(" (Ctrl-C stops)\n")
    assert [wall_time_text(s) for s in (0.42, 42, 200, 7500)] == [
        "0.4 s", "42 s", "3 min 20 s", "2 h 5 min"]


def test_a_long_progress_line_is_written_at_least_every_few_seconds(
        monkeypatch):
    """A long run off a terminal writes a line every LINE_INTERVAL s of
    wall time even between two tenths of the run."""
    import io

    from drake_wbc.experiments.runner import Progress

    monkeypatch.setattr(Progress, "LINE_INTERVAL", 0.0)
    stream = io.StringIO()
    meter = Progress("run", 3600.0, stream=stream)
    for t in (1.0, 2.0, 3.0):
        meter.update(t)
    assert len(stream.getvalue().splitlines()) == 3


def test_the_stress_progress_line_tells_the_time_left():
    import io

    from drake_wbc.stress.run import ProgressLine

    sound = dict(all_finite=True, max_base_command_ratio=0.5,
                 max_filter_state_ratio=0.5,
                 max_joint_speed_command_ratio=0.5,
                 min_command_joint_limit_margin_rad=0.1,
                 min_static_obstacle_distance_m=None)
    stream = io.StringIO()
    line = ProgressLine(2, stream=stream)
    line.update(dict(case=0, **sound))
    line.update(dict(case=1, **sound))
    first, last = stream.getvalue().splitlines()
    assert re.fullmatch(r"stress: 1 / 2 cases done, 0 failed, about "
                        r"[\d.]+ s left", first), first
    assert re.fullmatch(r"stress: 2 / 2 cases done, 0 failed, took "
                        r"[\d.]+ s", last), last


def test_a_short_run_says_which_metrics_it_cannot_measure(tmp_path,
                                                          capsys):
    assert main(["run", "trajectory_tracking", "--duration", "0.05",
                 "--no-replay", "--output", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert err.startswith(
        "drake-wbc run trajectory_tracking: note: the run ends at 0.05 s, "
        "before the step starts at 1 s: the step's metrics and the ratios "
        "will be nan (give a --duration past it, e.g. 2 s)\n")


@pytest.mark.parametrize("argv, message", [
    (["--duration", "0.5"],
     "--duration = 0.5 is not allowed with --sweep: must be at least 1.11 "
     "s (the step starts at 1 s and its error counts from 0.1 s later; a "
     "shorter run's ratios are all nan)"),
    (["fixed_point"],
     "scenario = 'fixed_point' is not allowed with --sweep: must be a "
     "trajectory-tracking scenario with the runs filtered and unfiltered "
     "(e.g. trajectory_tracking)")])
def test_a_sweep_it_cannot_measure_is_refused(argv, message, tmp_path,
                                              capsys):
    """`run --sweep --duration 0.5` ran every point of the maps for
    minutes to write ratios that were all NaN, without saying why."""
    assert main(["run", "--sweep", "--output", str(tmp_path / "o")]
                + argv) == 2
    out, err = capsys.readouterr()
    assert err == f"drake-wbc run: {message}\n"
    assert out == "" and not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv, message", [
    (["run", "--duration", "abc"],
     "drake-wbc run: --duration = 'abc' is not allowed: must be a number "
     "(see drake-wbc run --help)"),
    (["stress", "--cases", "1.5"],
     "drake-wbc stress: --cases = '1.5' is not allowed: must be a whole "
     "number (see drake-wbc stress --help)"),
    (["frob"],
     "drake-wbc: command = 'frob' is not allowed: must be one of run, "
     "bench, stress, teach, replay, bode, diagram, robot-sim, deploy, "
     "plot, demo (see drake-wbc --help)"),
    (["run", "--output", ""],
     "drake-wbc run: --output = '' is not allowed: must be a file or "
     "folder name (not empty) (see drake-wbc run --help)"),
    (["demo", "--robot", " "],
     "drake-wbc demo: --robot = ' ' is not allowed: must be a file or "
     "folder name (not empty) (see drake-wbc demo --help)"),
    (["replay", "m.yaml", "--goal", "1", "2"],
     "drake-wbc replay: --goal: expected 4 arguments (see drake-wbc "
     "replay --help)"),
    (["run", ""],
     "drake-wbc run: scenario = '' is not allowed: must be a scenario "
     "file or one of "),
])
def test_a_command_line_that_does_not_parse_is_one_line(argv, message,
                                                        tmp_path,
                                                        monkeypatch,
                                                        capsys):
    """argparse's errors were a usage block and 'error: argument
    --duration: invalid float value'; an empty --output was the current
    folder and an empty scenario the default one. Each is now one line
    naming the option, its value and what is allowed, exit code 2."""
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert err.startswith(message) and err.count("\n") == 1, err
    assert out == "" and list(tmp_path.iterdir()) == []


def test_help_and_version_still_exit_0(capsys):
    assert main(["--version"]) == 0
    assert main(["run", "--help"]) == 0
    assert "usage: drake-wbc run" in capsys.readouterr().out


def test_demo_names_its_page_after_a_robot_with_any_name(tmp_path, capsys):
    """A description named "acme/arm: v2" wrote its page into a folder
    acme that was not there (FileNotFoundError); the page's name keeps
    what a file name can hold, in the --output folder."""
    from drake_wbc.cli.main import file_stem

    path = write_omni_arm(tmp_path, 6)
    path.write_text(path.read_text().replace(
        "name: omni_arm", 'name: "acme/arm: v2"', 1))
    assert 'name: "acme/arm: v2"' in path.read_text()
    output = tmp_path / "pages"
    assert main(["demo", "--robot", str(path), "--output",
                 str(output)]) == 0
    out = capsys.readouterr().out
    assert "drake_wbc robot model 'acme/arm: v2'" in out
    assert [p.name for p in output.iterdir()] == ["acme_arm_v2_model.html"]
    assert file_stem("../../etc/passwd") == "etc_passwd"
    assert file_stem("..") == "robot" and file_stem("a" * 300) == "a" * 100
    assert file_stem("Ünï code") == "n_code"


@pytest.mark.parametrize("argv, option", [
    (["plot"], "logfile"), (["teach", "teach", "--log"], "--log")])
def test_a_file_that_is_no_lcm_log_is_named_as_typed(argv, option,
                                                     tmp_path, capsys):
    """It was named 'path = ...', a name no option has."""
    log = tmp_path / "notes.txt"
    log.write_text("not an LCM log\n")
    assert main(argv + [str(log), "--output", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.startswith(
        f"drake-wbc {argv[0]}: {option} = {str(log)!r} is not allowed: the "
        "log holds none of the channels")


def test_demo_names_a_controller_folder(tmp_path, capsys):
    assert main(["demo", "--controller", str(tmp_path), "--output",
                 str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == (
        f"drake-wbc demo: --controller = {str(tmp_path)!r} is not allowed: "
        "a folder, not a controller parameters file\n")


def test_replay_refuses_a_start_that_makes_the_run_endless(tmp_path,
                                                           capsys):
    movement = (Path(__file__).resolve().parents[1] / "diagrams"
                / "movements" / "teach.yaml")
    assert main(["replay", str(movement), "--start-time", "1e300",
                 "--output", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == (
        "drake-wbc replay: the movement's run (--start-time = 1e+300) = "
        "1e+300 is not allowed: must be at most 3600 s (an hour); give a "
        "shorter --tau or --start-time, or a --duration\n")
    assert main(["replay", str(movement), "--duration", "0.001",
                 "--output", str(tmp_path / "o")]) == 2
    assert "--duration = 0.001 is not allowed: must be at least" in (
        capsys.readouterr().err)
    assert not (tmp_path / "o").exists()


def test_stress_refuses_more_cases_or_workers_than_it_can_run(tmp_path,
                                                              capsys):
    """`stress --cases 1e12` listed a trillion case numbers before it ran
    one, and `--workers 1000` started a process a case, each loading
    Drake, on a machine of two cores."""
    import os

    from drake_wbc.stress.run import MAX_CASES, WORKERS_PER_CORE

    output = tmp_path / "o"
    assert main(["stress", "--cases", "1000000000000", "--output",
                 str(output)]) == 2
    assert capsys.readouterr().err == (
        "drake-wbc stress: --cases = 1000000000000 is not allowed: must be "
        f"at most {MAX_CASES} (a case takes seconds; run more as several "
        "runs of other seeds)\n")
    cores = os.cpu_count() or 1
    most = WORKERS_PER_CORE * cores
    assert main(["stress", "--cases", "2", "--workers", str(most + 1),
                 "--output", str(output)]) == 2
    assert capsys.readouterr().err.startswith(
        f"drake-wbc stress: --workers = {most + 1} is not allowed: must be "
        f"at most {most} ({WORKERS_PER_CORE} a core, of this machine's "
        f"{cores}; ")
    assert not output.exists()


def test_replay_refuses_a_goal_off_the_site(tmp_path, capsys):
    """`replay --goal 1e300 0 0 0` ran, tripped the controller's safety
    stop and reported a goal error of inf, exit code 0."""
    movement = (Path(__file__).resolve().parents[1] / "diagrams"
                / "movements" / "teach.yaml")
    assert main(["replay", str(movement), "--goal", "1e300", "0", "0", "0",
                 "--output", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == (
        "drake-wbc replay: --goal = [1e+300, 0.0, 0.0, 0.0] is not allowed: "
        "every coordinate and size of a scene must lie within +-1000 m (the "
        "site around the robot)\n")
    assert not (tmp_path / "o").exists()
