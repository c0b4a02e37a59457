"""`drake-wbc bode` and `drake-wbc diagram` (drake_wbc.cli.analysis):
they run on the default scenario and write well-formed files."""

import argparse
import contextlib
import csv
import io
from pathlib import Path

import numpy as np
import pytest

from drake_wbc.analysis.bode import read_csv
from drake_wbc.cli import analysis as commands
from drake_wbc.cli.robot_option import on_robot
from drake_wbc.experiments.scenario import (
    controller_arm,
    find_scenario,
    load_scenario,
    scenario_robot,
)
from drake_wbc.robot.description import shipped_robot

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PLOTS = ("base_filter", "split_ideal", "split_base_loop", "base_plant",
         "dmp_force", "contact_loops", "filter_sweep", "split_sweep")
TABLE_ROWS = (
    "base filter, h = 0.01 s", "base filter, continuous",
    "split: sum: end effector", "with base loop: sum: end effector",
    "base velocity loop alone", "base loop and plant: base velocity",
    "end effector with the base loop and the plant",
    "base velocity, driver and plant", "end effector, driver and plant",
    "arm CDMP, stiffness axis",
    "arm CDMP, force axis", "whole-body CDMP, S_hri = 1",
    "contact loop, admittance axis, DMP alone, no delay",
    "contact loop, admittance axis, 2 periods to motion",
    "contact loop, admittance axis, 3 periods to motion",
    "contact loop, stiffness axis, DMP alone, no delay",
    "contact loop, stiffness axis, 2 periods to motion",
    "contact loop, stiffness axis, 3 periods to motion")


def _parse(add_arguments, argv):
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(argv)


def _run(run, args):
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = run(args)
    return code, out.getvalue()


@pytest.fixture(scope="module")
def bode(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bode")
    args = _parse(commands.add_bode_arguments, ["--output", str(folder)])
    assert args.scenario is None  # the default scenario
    progress = io.StringIO()
    with contextlib.redirect_stderr(progress):
        code, text = _run(commands.run_bode, args)
    return code, text, folder, progress.getvalue()


def test_bode_writes_every_plot_and_table(bode):
    code, text, folder, _ = bode
    assert code == 0
    assert "drake-wbc bode trajectory_tracking" in text
    for name in PLOTS:
        assert (folder / f"{name}.png").read_bytes()[:8] == PNG_SIGNATURE
        header, data = read_csv(folder / f"{name}.csv")
        assert header[:2] == ["frequency_hz", "omega_rad_s"]
        assert len(header) == data.shape[1] >= 4
        assert (len(header) - 2) % 2 == 0
        assert data.shape[0] > 100 and np.all(np.isfinite(data))
        assert np.all(np.diff(data[:, 0]) > 0)
        assert np.allclose(data[:, 1], 2 * np.pi * data[:, 0])
    for row in TABLE_ROWS:
        assert any(line.startswith(row) for line in text.splitlines()), row
    with (folder / "summary.csv").open(newline="") as stream:
        summary = list(csv.reader(stream))
    assert summary[0][0] == "name" and "phase_margin_deg" in summary[0]
    assert {row[0] for row in summary[1:]} >= set(TABLE_ROWS)
    assert all(len(row) == len(summary[0]) for row in summary)


def test_bode_says_each_part_as_it_starts(bode):
    """The parts are said on stderr as they start, in order (the table
    and the notes stay on stdout)."""
    *_, progress = bode
    parts = ("the base filter", "the split of V_ee", "the coupled DMPs",
             "the sweeps")
    lines = progress.splitlines()
    assert len(lines) == len(parts)
    for line, part in zip(lines, parts, strict=True):
        assert line.startswith(f"drake-wbc bode trajectory_tracking: {part}")


def test_bode_ideal_split_is_flat(bode):
    _, _, folder, _ = bode
    header, data = read_csv(folder / "split_ideal.csv")
    total = header.index("sum: end effector magnitude_db")
    assert np.abs(data[:, total]).max() < 1e-9
    assert np.abs(data[:, total + 1]).max() < 1e-9
    base = header.index("base share J_b V_b^flt magnitude_db")
    assert data[0, base] == pytest.approx(20 * np.log10(0.5), abs=0.01)


def test_bode_shows_the_plant(bode):
    _, text, folder, _ = bode
    header, data = read_csv(folder / "split_base_loop.csv")
    plant = header.index(
        "end effector with the base loop and the plant magnitude_db")
    driver = header.index("sum: end effector magnitude_db")
    # At low frequency the plant follows the driver's loop.
    assert data[0, plant] == pytest.approx(data[0, driver], abs=0.05)
    assert ("end effector with the base loop and the plant: |V_ee,actual"
            in text)
    # The mount's rocking mode lifts the end effector's response to the
    # base's command above the base's own around 5 Hz.
    header, data = read_csv(folder / "base_plant.csv")
    base = header.index("base velocity, driver and plant magnitude_db")
    tool = header.index("end effector, driver and plant magnitude_db")
    lift = data[:, tool] - data[:, base]
    assert 4.0 < data[np.argmax(lift), 0] < 6.0 and lift.max() > 6.0


def test_bode_table_reports_the_contact_loop_margins(bode):
    _, text, _, _ = bode
    line = next(x for x in text.splitlines() if x.startswith(
        "contact loop, admittance axis, DMP alone, no delay"))
    # The discrete integrator K k_f h / (z - 1) with K k_f h = 0.3: gain
    # margin 2 / 0.3 at the Nyquist frequency; |L| = 1 where
    # 2 sin(w h / 2) = 0.3, with the phase margin 90 - w h / 2 degrees.
    assert f"{20 * np.log10(2 / 0.3):.2f}" in line.split()
    assert f"{90 - np.degrees(np.arcsin(0.15)):.1f}" in line.split()
    # The base filter, eq. (filtering), critically damped at 1 Hz: 3 dB
    # down at sqrt(10^0.15 - 1) Hz, continuous and held alike (to the
    # table's three decimals).
    for row in ("base filter, h = 0.01 s", "base filter, continuous"):
        line = next(x for x in text.splitlines() if x.startswith(row))
        assert line[len(row):].split()[:2] == [
            "-0.00", f"{np.sqrt(10**0.15 - 1):.3f}"]


def critical_gain(delay):
    """The largest g for which g z^-delay / (z - 1) is stable in a
    negative feedback loop: bisection on the roots of its characteristic
    polynomial z^(delay + 1) - z^delay + g."""
    low, high = 0.0, 3.0
    while high - low > 1e-12:
        g = 0.5 * (low + high)
        polynomial = np.zeros(delay + 2)
        polynomial[:2] = 1.0, -1.0
        polynomial[-1] += g
        if np.abs(np.roots(polynomial)).max() < 1.0:
            low = g
        else:
            high = g
    return low


def test_bode_table_puts_the_delay_to_the_arms_motion_in_the_contact_loop(
        bode):
    """The contact loop's margin of the DMP alone, K k_f h / (z - 1), is
    2 / 0.3 (16.48 dB); with the two to three control periods from a
    reading to the arm's motion, K k_f h z^-d / (z - 1), it is the
    critical gain of that loop over 0.3: 6.28 dB (d = 2) and 3.43 dB
    (d = 3). The table printed the first alone, as the contact loop's."""
    _, text, _, _ = bode
    lines = text.splitlines()
    for delay, label in ((0, "DMP alone, no delay"),
                         (2, "2 periods to motion"),
                         (3, "3 periods to motion")):
        row = f"contact loop, admittance axis, {label}"
        line = next(x for x in lines if x.startswith(row))
        expected = 20 * np.log10(critical_gain(delay) / 0.3)
        assert line[len(row):].split()[4] == f"{expected:.2f}"
    assert critical_gain(3) == pytest.approx(0.445, abs=5e-4)


def test_bode_table_gives_an_integrator_no_dc_gain(bode):
    """The force axis of the arm's CDMP and the whole body's admittance
    are eq. (tf-admit), D_a / s: an infinite DC gain and no bandwidth
    (not the gain at the grid's 0.01 Hz and 1.41 times that)."""
    _, text, _, _ = bode
    for row in ("arm CDMP, force axis", "whole-body CDMP, S_hri = 1",
                "contact loop, admittance axis, DMP alone, no delay",
                "contact loop, admittance axis, 3 periods to motion"):
        line = next(x for x in text.splitlines() if x.startswith(row))
        dc, bandwidth, peak, at = line[len(row):].split()[:4]
        assert (dc, bandwidth, peak, at) == ("inf", "-", "inf", "0.000")


def test_bode_rejects_an_unknown_scenario(tmp_path):
    args = _parse(commands.add_bode_arguments,
                  ["no_such_scenario", "--output", str(tmp_path)])
    with pytest.raises(ValueError, match="no_such_scenario"):
        commands.run_bode(args)


@pytest.mark.parametrize("command", ["bode", "diagram"])
def test_an_empty_scenario_or_output_is_refused(command, tmp_path,
                                                monkeypatch, capsys):
    """`bode ''` analysed the default scenario and `--output ''` wrote
    into the current folder; both are refused in one line."""
    from drake_wbc.cli.main import main

    monkeypatch.chdir(tmp_path)
    assert main([command, ""]) == 2
    assert capsys.readouterr().err.startswith(
        f"drake-wbc {command}: scenario = '' is not allowed: must be a "
        "scenario file or one of ")
    assert main([command, "--output", ""]) == 2
    assert capsys.readouterr().err == (
        f"drake-wbc {command}: --output = '' is not allowed: must be a file "
        f"or folder name (not empty) (see drake-wbc {command} --help)\n")
    assert list(tmp_path.iterdir()) == []


def test_diagram_writes_dot_and_says_when_graphviz_is_missing(
        tmp_path, monkeypatch):
    empty = tmp_path / "empty_path"
    empty.mkdir()
    monkeypatch.setenv("PATH", str(empty))
    folder = tmp_path / "diagram"
    args = _parse(commands.add_diagram_arguments,
                  ["trajectory_tracking", "--output", str(folder)])
    code, text = _run(commands.run_diagram, args)
    assert code == 0
    for stem, name in (("controller", "cdmp_wbc_controller"),
                       ("station", "simulated_station")):
        dot = (folder / f"{stem}.dot").read_text()
        assert dot.lstrip().startswith("digraph")
        assert dot.count("{") == dot.count("}")
        assert name in dot
        assert not (folder / f"{stem}.svg").exists()
    assert "Graphviz's `dot` program is not on PATH" in text
    assert commands.render_svg(folder / "controller.dot") is None


def test_diagram_draws_the_station_of_the_scenarios_robot(tmp_path):
    """A scenario on the second shipped robot: the station's diagram is
    of its 7-joint arm, as the controller's is (the station was built of
    the shipped robot, whose 6 joints refused the scenario's 7 initial
    positions)."""
    folder = tmp_path / "diagram"
    args = _parse(commands.add_diagram_arguments,
                  ["trajectory_tracking_lbr", "--output", str(folder)])
    code, _ = _run(commands.run_diagram, args)
    assert code == 0
    station = (folder / "station.dot").read_text()
    robot = scenario_robot(
        load_scenario(find_scenario("trajectory_tracking_lbr")))
    shipped = shipped_robot()
    assert len(robot.arm.joints) == 7
    # The plant's ports are named by model instance: the arm's scope.
    arm, shipped_arm = (r.arm.joints[0].split("::")[0]
                        for r in (robot, shipped))
    assert f"{arm}_state" in station
    assert f"{shipped_arm}_state" not in station


def test_the_chains_are_linearised_on_the_scenarios_robot():
    """`bode --robot` on the second shipped robot: the operating point is
    its 7-joint arm at home with its own tuning (C_m with its k_j 6e4),
    and the ideal split of the end effector's command still sums to one
    through that arm's stages."""
    from pydrake.systems.primitives import Linearize

    from drake_wbc.analysis import chains
    from drake_wbc.robot.tuning import capability_at

    lbr = (Path(__file__).resolve().parents[1] / "models"
           / "lbr_omni.robot.yaml")
    args = _parse(commands.add_bode_arguments,
                  ["trajectory_tracking", "--robot", str(lbr)])
    scenario = on_robot(load_scenario(find_scenario(args.scenario)), args,
                        echo=None)
    arm = controller_arm(scenario)
    assert arm.num_joints == 7
    point = chains.operating_point(scenario.controller,
                                   scenario.station.initial_arm_positions,
                                   arm)
    np.testing.assert_array_equal(point.arm_positions, arm.home)
    assert point.capability == pytest.approx(
        capability_at(arm, arm.home, 6.0e4), rel=1e-12)
    split = chains.build_split_diagram(scenario.controller, point)
    context = split.CreateDefaultContext()
    split.get_input_port().FixValue(context, np.zeros(6))
    linear = Linearize(split, context)
    np.testing.assert_allclose(linear.D()[12:18], np.eye(6), atol=1e-12)
    np.testing.assert_allclose(linear.C()[12:18], 0.0, atol=1e-12)


def test_the_dmp_figures_closed_forms_check_its_responses():
    """Each dashed closed form of dmp_force lies on the discrete response
    it is drawn over, on the whole band up to the Nyquist frequency (the
    continuous eqs. (lp-admit) and (tf-admit) once drawn there part from
    the stages' responses by up to 88 degrees and 3.7 dB near 50 Hz)."""
    from drake_wbc.analysis import report
    from drake_wbc.analysis.frequency import frequency_grid

    params = load_scenario(find_scenario("trajectory_tracking")).controller
    h = params.time_step
    hertz, omega = frequency_grid(0.01, 0.5 / h, 60)
    bode = report.BodeReport()
    report._dmp_plots(bode, params, hertz, omega, h,
                      report.CONTACT_STIFFNESS)
    curves = {c.label: c for c in bode.plots["dmp_force"].curves}
    pairs = (("arm CDMP, stiffness axis", "eq. (lp-admit), ZOH"),
             ("arm CDMP, force axis", "eq. (tf-admit), D_a = k_f, ZOH"),
             ("whole-body CDMP, S_hri = 1",
              "eq. (tf-admit), D_a = k_hri, ZOH"))
    assert {c for _, c in pairs} == {
        label for label, c in curves.items() if c.closed_form}
    for response, closed in pairs:
        np.testing.assert_allclose(curves[response].response,
                                   curves[closed].response, rtol=1e-6)


def test_diagram_says_in_one_line_when_dot_fails(tmp_path, monkeypatch,
                                                 capsys):
    """A `dot` that fails (here a script that says two lines and exits 1)
    ended `drake-wbc diagram` in a traceback: it says so in one line,
    keeps both .dot files and exits 1."""
    from drake_wbc.cli.main import main

    programs = tmp_path / "bin"
    programs.mkdir()
    dot = programs / "dot"
    dot.write_text("#!/bin/sh\necho 'Error: syntax error in line 3' >&2\n"
                   "echo 'near: ->' >&2\nexit 1\n")
    dot.chmod(0o755)
    monkeypatch.setenv("PATH", str(programs))
    folder = tmp_path / "diagram"
    assert main(["diagram", "trajectory_tracking", "--output",
                 str(folder)]) == 1
    err = capsys.readouterr().err
    assert err == (
        f"drake-wbc diagram trajectory_tracking: dot failed on "
        f"{folder / 'controller.dot'} (exit 1): Error: syntax error in "
        f"line 3; near: ->; the .dot files are kept in {folder}/\n")
    for stem in ("controller", "station"):
        assert (folder / f"{stem}.dot").read_text().lstrip().startswith(
            "digraph")
