"""`drake-wbc bench`: the arguments and the run.

    drake-wbc bench [--quick] [--output DIR] [--repeats N] [--robot FILE]

measures, in one process and interleaved (drake_wbc.bench.timing), in
wall-clock and in the thread's CPU time: the closed-form motion
distribution against DAQP, ProxQP, quadprog and Drake's DiffIK called
directly and QPs through qpsolvers, given the same kinematics and with
it, beside the kinematics alone (bench.distribution_race); one control
tick whole and per stage (bench.control_tick); the cost against the
number of obstacle
points and the control rate, and, each in a child process, every
scenario's real-time factor and peak memory (bench.scenarios). It prints
the tables and writes bench.json and bench.md to the output folder.

With `--robot FILE` (a robot description, drake_wbc.robot.description)
every part times that robot: the race on its arm's joints and mounting,
the tick of its controller (its limits, footprint and tuning) against
measurements near its home and obstacle points outside its footprint,
and the scenarios on it (as `drake-wbc run SCENARIO --robot FILE`), those
that do not apply to it skipped. Without it, the shipped robot (and
each scenario's own), as before.
"""

import warnings
from pathlib import Path

from drake_wbc.bench import report, timing
from drake_wbc.math.validation import positive_duration, whole_number

FULL = dict(repeats=30, problems=200, ticks=100, scaling_ticks=50,
            points=(100, 250, 500, 1000, 2000),
            rates=(100.0, 200.0, 500.0, 1000.0),
            scenarios=None, scenario_duration=None)
"""The settings of a full run (scenarios None: all of them, for their
whole duration)."""

QUICK = dict(repeats=5, problems=20, ticks=20, scaling_ticks=10,
             points=(100, 2000), rates=(100.0, 1000.0),
             scenarios=("trajectory_tracking",), scenario_duration=1.0)
"""The settings of --quick: a few seconds of each part."""

FAIRNESS_TOLERANCE = 1e-8
"""Largest allowed difference of V_wb between same-problem contenders
(the race stops before any timing if one differs more): the direct
solvers agree to about 1e-16 (ProxQP to 1e-12), the qpsolvers back-ends
with their tightened tolerances to 1e-10."""

OSQP_NOTICE = "The default value of raise_error will change"
"""The start of a notice osqp prints on every solve, silenced."""

TICK_POINTS = 300
"""Obstacle points of the control-tick part (a person and some walls)."""


def add_bench_arguments(parser):
    """Adds the arguments of `drake-wbc bench` to `parser`."""
    parser.add_argument("--quick", action="store_true",
                        help="a short run: few repetitions, one scenario "
                             "for one simulated second")
    parser.add_argument("--output", type=Path, default=Path("out/bench"),
                        help="output folder (default: %(default)s)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="timed repetitions of each micro-benchmark, "
                             f"at most {MAX_REPEATS} (default: "
                             f"{FULL['repeats']}, quick {QUICK['repeats']})")
    parser.add_argument("--scenario-repeats", type=int, default=1,
                        help="runs of each scenario, at most "
                             f"{MAX_SCENARIO_REPEATS} (default: "
                             "%(default)s)")
    parser.add_argument("--scenario-duration", type=float, default=None,
                        help="simulated seconds of each scenario (default: "
                             "the scenario's, 1 with --quick)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the random problems (default: "
                             "%(default)s)")
    parser.add_argument("--profile", action="store_true",
                        help="also write cProfile reports of the control "
                             "tick and of a scenario")
    parser.add_argument(
        "--robot", type=Path, default=None,
        help="time the race, the control tick and the scenarios on the "
             "robot of this description YAML (default: the shipped robot, "
             "and each scenario's own)")


MAX_REPEATS = 1000
"""The most timed repetitions `--repeats` asks for: the full bench's 30
of the race and the ticks take about half a minute on a 2-core machine,
so 1000 take some 20 minutes."""

MAX_SCENARIO_REPEATS = 100
"""The most runs of each scenario `--scenario-repeats` asks for: the
full bench's one run of every scenario takes about half a minute on a
2-core machine, so 100 take some 40 minutes."""


def settings_from(args):
    """The run's settings (a dict like FULL) from parsed arguments."""
    settings = dict(QUICK if args.quick else FULL)
    if args.repeats is not None:
        settings["repeats"] = whole_number(
            "--repeats", args.repeats, 1, MAX_REPEATS,
            " (some 20 minutes on a 2-core machine)")
    if args.scenario_duration is not None:
        settings["scenario_duration"] = positive_duration(
            "--scenario-duration", args.scenario_duration)
    settings["scenario_repeats"] = whole_number(
        "--scenario-repeats", args.scenario_repeats, 1, MAX_SCENARIO_REPEATS,
        " (some 40 minutes on a 2-core machine)")
    settings["seed"] = whole_number("--seed", args.seed)
    settings["quick"] = bool(args.quick)
    robot = getattr(args, "robot", None)
    if robot is not None:
        from drake_wbc.experiments.scenario import robot_option_file

        robot = str(robot_option_file(robot).resolve())
    settings["robot"] = robot
    return settings


def bench_arm(settings):
    """The ArmKinematics the race and the ticks time: that of the robot
    of settings["robot"] (a description's file), the shipped robot's if
    None.

    Raises:
        ValueError: naming the file and the field of a description that
            does not load.
    """
    from drake_wbc.robot.description import load_robot_description
    from drake_wbc.robot.model import ArmKinematics, make_robot_plant

    if settings.get("robot") is None:
        return ArmKinematics()
    description = load_robot_description(settings["robot"])
    return ArmKinematics(*make_robot_plant(description))


def _stats(times, name, reference=None):
    """time_us and cpu_us of contender `name` (timing.interleave's
    result), and its ratio to `reference` (wall and CPU) if given."""
    entry = dict(
        time_us=timing.scaled(timing.summarize(times[name]), 1e6),
        cpu_us=timing.scaled(timing.summarize(times.cpu[name]), 1e6))
    if reference is not None:
        entry["ratio"] = timing.summarize(times[name] / times[reference])
        entry["cpu_ratio"] = timing.summarize(
            times.cpu[name] / times.cpu[reference])
    return entry


def bench_distribution(arm, settings):
    """Part 1: the fairness check (raises if a same-problem contender
    disagrees), then the interleaved race: the kinematics alone, the QP
    peers' data preparation alone, every solver given the same p_ee, and
    every solver with the kinematics first."""
    from drake_wbc.bench import distribution_race as race

    problems = race.make_problems(settings["problems"], settings["seed"],
                                  arm)
    given = race.given_data(arm, problems)
    solvers = race.make_solvers(arm)
    informative = {"drake_diffik_plant": race.PlantDiffIk(arm)}
    fairness = race.fairness(problems, solvers, given, informative)
    unfair = {name: entry["max_abs_difference"]
              for name, entry in fairness.items()
              if entry["same_problem"]
              and not entry["max_abs_difference"] <= FAIRNESS_TOLERANCE}
    if unfair:
        raise RuntimeError(
            f"the race is not fair: {unfair} differ from closed_form's V_wb"
            f" by more than {FAIRNESS_TOLERANCE:g}")
    contenders = {
        "kinematics": race.batch(race.kinematics_of(arm), problems),
        "qp_data": race.batch(race.qp_data(arm), problems,
                              [g.p_ee for g in given])}
    for name, solve in solvers.items():
        contenders[f"solve:{name}"] = race.batch(solve, problems, given)
        contenders[f"with_kinematics:{name}"] = race.batch(
            race.with_kinematics(arm, solve), problems)
    for name, solve in informative.items():
        contenders[f"with_kinematics:{name}"] = race.batch(solve, problems)
    times = timing.interleave(contenders, settings["repeats"])
    parts = {"solve": {}, "with_kinematics": {}}
    for part, entries in parts.items():
        reference = f"{part}:{race.REFERENCE}"
        for key in times:
            if key.startswith(part + ":"):
                name = key.split(":", 1)[1]
                entries[name] = dict(_stats(times, key, reference),
                                     **fairness[name])
    return dict(problems=len(problems), tolerance=FAIRNESS_TOLERANCE,
                fair=True, kinematics=_stats(times, "kinematics"),
                qp_data=_stats(times, "qp_data"), **parts)


def bench_tick(arm, settings):
    """Part 2: the full tick (new measurements every tick, the station's
    commands pulled), the same without the pull, the framework floor,
    and each stage beside its hollow twin."""
    from drake_wbc.bench.control_tick import ControllerTicker, stage_tickers
    from drake_wbc.bench.framework_floor import FloorTicker

    ticker = ControllerTicker(arm, num_points=TICK_POINTS)
    floor = FloorTicker(ticker)
    stages = stage_tickers(ticker)
    hollow = stage_tickers(floor)
    n = settings["ticks"]
    contenders = {"tick": ticker.ticks(n),
                  "tick_unpulled": ticker.ticks(n, pull=False),
                  "tick_floor": floor.ticks(n)}
    for name, stage in stages.items():
        contenders[f"stage:{name}"] = stage.contender(n)
        contenders[f"hollow:{name}"] = hollow[name].contender(n)
        contenders[f"inputs:{name}"] = stage.contender(n, inputs_only=True)
    times = timing.interleave(contenders, settings["repeats"])

    def us(key):
        return _stats(times, key)

    return dict(
        rate_hz=1.0 / ticker.time_step, obstacle_points=TICK_POINTS,
        measurement_sets=len(ticker.values),
        tick=us("tick"), tick_unpulled=us("tick_unpulled"),
        framework_floor=us("tick_floor"),
        stages={name: dict(tick=us(f"stage:{name}"),
                           hollow=us(f"hollow:{name}"),
                           inputs=us(f"inputs:{name}"))
                for name in stages})


def bench_scaling(arm, settings):
    """Part 4: ticks per second against obstacle points and control
    rate (one ticker each, all interleaved)."""
    from drake_wbc.bench.control_tick import ControllerTicker

    configs = [("obstacle_points", points, 100.0)
               for points in settings["points"]]
    configs += [("control_rate", TICK_POINTS, rate)
                for rate in settings["rates"]]
    tickers = {(kind, points, rate): ControllerTicker(
        arm, time_step=1.0 / rate, num_points=points)
        for kind, points, rate in configs}
    n = settings["scaling_ticks"]
    times = timing.interleave({key: t.ticks(n) for key, t in tickers.items()},
                              settings["repeats"])
    result = {"obstacle_points": [], "control_rate": []}
    for key, samples in times.items():
        kind, points, rate = key
        stats = timing.scaled(timing.summarize(samples), 1e6)
        result[kind].append(dict(
            points=points, rate_hz=rate, tick_us=stats,
            cpu_us=timing.scaled(timing.summarize(times.cpu[key]), 1e6),
            ticks_per_second=1e6 / stats["median"],
            load=stats["median"] * 1e-6 * rate))
    return result


def bench_scenarios(settings, echo=print):
    """Part 3: each scenario in a child process."""
    from drake_wbc.bench.scenarios import measure_scenarios
    from drake_wbc.experiments.scenario import find_scenario, scenario_files

    names = settings["scenarios"]
    paths = (scenario_files() if names is None
             else [find_scenario(name) for name in names])
    results = measure_scenarios(paths, settings["scenario_duration"],
                                settings["scenario_repeats"], echo=echo,
                                robot=settings.get("robot"))
    for entry in results.values():
        if "skipped" not in entry:
            entry["chunk_real_time_factor_stats"] = timing.summarize(
                entry.pop("chunk_real_time_factor"))
    return results


def run_benchmarks(settings, echo=print):
    """Every part with `settings` (see FULL; its "robot", a
    description's file or None, the robot timed); returns the results
    dict (environment, settings, robot, distribution, control_tick,
    scaling, scenarios, goals)."""
    arm = bench_arm(settings)
    results = {"environment": timing.environment(),
               "settings": {k: (list(v) if isinstance(v, tuple) else v)
                            for k, v in settings.items()},
               "robot": dict(name=arm.model.description.name,
                             arm_joints=arm.num_joints)}
    parts = (("distribution", "motion distribution race",
              lambda: bench_distribution(arm, settings)),
             ("control_tick", "control tick, whole and per stage",
              lambda: bench_tick(arm, settings)),
             ("scaling", "obstacle points and control rate",
              lambda: bench_scaling(arm, settings)),
             ("scenarios", "scenarios, each in a child process",
              lambda: bench_scenarios(settings, echo)))
    for key, label, part in parts:
        echo(f"bench: {label} ...")
        results[key] = part()
    results["goals"] = report.evaluate_goals(results)
    return results


def run_bench(args, echo=print):
    """Runs `drake-wbc bench` with parsed `args`; returns the exit code
    (0; the goals are reported, not enforced)."""
    settings = settings_from(args)
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        # osqp 1.x announces a change of a default on every solve.
        warnings.filterwarnings("ignore", OSQP_NOTICE)
        results = run_benchmarks(settings, echo)
    text = report.markdown(results)
    (output / "bench.md").write_text(text)
    report.write_json(results, output / "bench.json")
    echo("")
    echo(text)
    if args.profile:
        _write_profiles(output, settings, echo, arm=bench_arm(settings))
    echo(f"Written to {output}/: bench.json, bench.md"
         + (", profile_tick.txt, profile_scenario.txt"
            if args.profile else ""))
    return 0


def _write_profiles(output, settings, echo, arm):
    from drake_wbc.bench import profiling
    from drake_wbc.bench.control_tick import make_ticker
    from drake_wbc.experiments.scenario import find_scenario

    echo("bench: profiling ...")
    ticker = make_ticker(arm, num_points=TICK_POINTS)
    (output / "profile_tick.txt").write_text(
        profiling.profile_ticks(ticker, 50 if settings["quick"] else 500))
    (output / "profile_scenario.txt").write_text(profiling.profile_scenario(
        find_scenario("trajectory_tracking"),
        0.5 if settings["quick"] else 2.0, robot=settings.get("robot")))

