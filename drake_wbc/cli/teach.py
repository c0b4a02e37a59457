"""`drake-wbc teach` and `drake-wbc replay`: teach a whole-body movement by
hand and repeat it (drake_wbc.math.movement).

    drake-wbc teach teach
    drake-wbc teach teach --log robot.lcmlog --start 2 --stop 9
    drake-wbc replay diagrams/movements/teach.yaml --goal 1.9 0.2 0.7 -2.7
    drake-wbc replay diagrams/movements/teach.yaml --tau 1.5
    drake-wbc replay diagrams/movements/teach.yaml --obstacle 0.6 -0.6 0.1

`teach` runs a teaching scenario in simulation (or reads an lcm-logger
log of the robot, `--log`), cuts the demonstration between the S_hri
markers (or `--start`/`--stop`), learns the DMP, writes the movement file,
the log, a figure of the demonstration against the learned rollout and
summary.json, and prints the summary. `replay` runs the repeat scenario
with the movement (to `--goal`, with `--tau`, around an `--obstacle`) and
writes what `drake-wbc run` writes, the figures of demonstration against
replay included.
"""

import shlex
import sys
from dataclasses import replace
from pathlib import Path

from drake_wbc.cli.robot_option import add_robot_argument, on_robot


def add_teach_arguments(parser):
    """The arguments of `drake-wbc teach`."""
    from drake_wbc.math.movement import DEFAULT_NUM_BASIS

    parser.add_argument(
        "scenario", help="the teaching scenario's name or YAML file (e.g. "
        "teach); with --log, the scenario the robot ran (its markers and "
        "controller)")
    parser.add_argument("--log", type=Path, default=None,
                        help="learn from this lcm-logger log of the robot "
                             "instead of simulating")
    parser.add_argument("--start", type=float, default=None,
                        help="the demonstration's start in s (default: "
                             "where S_hri turns 1)")
    parser.add_argument("--stop", type=float, default=None,
                        help="the demonstration's end in s (default: where "
                             "S_hri turns 0 again)")
    parser.add_argument("--num-basis", type=int, default=None,
                        help="basis functions of the forcing term "
                             f"(default: {DEFAULT_NUM_BASIS})")
    parser.add_argument("--output", type=Path, default=None,
                        help="output folder (default: out/teach_<scenario>)")
    parser.add_argument("--movement", type=Path, default=None,
                        help="the movement file to write (default: "
                             "<output>/movement.yaml)")
    add_robot_argument(parser, "teach")


def run_teach(args, argv=None, echo=print):
    """Runs `drake-wbc teach` (see the module's docstring); returns 0.

    `argv`: the arguments after `drake-wbc` (the subcommand first), for
    the movement file's header (the process's arguments if None)."""
    import numpy as np

    from drake_wbc.experiments import teach
    from drake_wbc.experiments.reports import (
        format_summary,
        json_text,
        plain_values,
    )
    from drake_wbc.experiments.scenario import find_scenario, load_scenario
    from drake_wbc.math.dmp import MAX_BASIS

    if args.num_basis is not None and not 1 <= args.num_basis <= MAX_BASIS:
        raise ValueError(f"--num-basis = {args.num_basis!r} is not allowed: "
                         f"must be 1 to {MAX_BASIS}")
    path = find_scenario(args.scenario)
    scenario = on_robot(load_scenario(path), args, echo)
    options = ("--start", "--stop")
    # The markers, before the run.
    start, stop = teach.interval(scenario, args.start, args.stop,
                                 names=options)
    if args.log is None and (
            (args.start is not None and start < 0.0)
            or (args.stop is not None and stop > scenario.duration)):
        # Known before the run, which would only be thrown away.
        raise ValueError(
            f"--start = {start!r} s, --stop = {stop!r} s is not allowed: "
            "must be an interval of the simulated run (from 0 to "
            f"{scenario.duration:g} s)")
    if args.log is not None and not Path(args.log).is_file():
        raise ValueError(f"--log = {str(args.log)!r} is not allowed: "
                         + ("a folder, not an LCM log"
                            if Path(args.log).is_dir() else "no such file"))
    output = args.output or Path("out") / f"teach_{path.stem}"
    output.mkdir(parents=True, exist_ok=True)
    written = []
    if args.log is not None:
        from drake_wbc.deployment.lcm_logs import read_lcm_log

        try:
            log = read_lcm_log(args.log, scenario.hardware)
        except ValueError as error:  # the log file's, named as typed
            if not str(error).startswith("path = "):
                raise
            raise ValueError(
                f"--log{str(error).removeprefix('path')}") from None
    else:
        from drake_wbc.experiments.runner import build_closed_loop, simulate

        log = simulate(build_closed_loop(scenario, scenario.variants[0]),
                       progress=echo is not None)
        saved = log.save(output / "log_teach")
        written += [saved, saved.with_suffix(".csv")]
    argv = sys.argv[1:] if argv is None else argv
    source = "drake-wbc " + shlex.join(argv)
    movement = teach.learn_from_log(scenario, log, args.start, args.stop,
                                    args.num_basis, source=source,
                                    names=options)
    file = movement.save(args.movement or output / "movement.yaml")
    figure = teach.draw_movement(movement, output, "teach",
                                 f"teach {path.stem}: demonstration "
                                 "against the learned DMP")
    metrics = teach.movement_metrics(movement, start, stop)
    metrics["num_basis"] = movement.params.num_basis
    metrics["goal"] = np.round(movement.goal, 4)
    summary = {"scenario": path.stem, "description": scenario.description,
               "experiment": "teach", "runs": {},
               "metrics": plain_values(metrics),
               "files": [f.name for f in written + [figure]],
               "movement": str(file)}
    (output / "summary.json").write_text(json_text(summary))
    if echo is not None:
        echo(format_summary(summary, output))
        echo(f"Movement written to {file}")
    return 0


def add_replay_arguments(parser):
    """The arguments of `drake-wbc replay`."""
    parser.add_argument("movement", type=Path,
                        help="a movement file written by drake-wbc teach")
    parser.add_argument("--goal", type=float, nargs=4, default=None,
                        metavar=("X", "Y", "Z", "YAW"),
                        help="the TCP's goal in the world, m and rad "
                             "(default: the demonstrated one)")
    parser.add_argument("--tau", type=float, default=None,
                        help="temporal scaling (default: the learned one; "
                             "2 is twice as slow)")
    parser.add_argument("--obstacle", type=float, nargs=3, action="append",
                        default=None, metavar=("X", "Y", "R"),
                        help="add a pillar of radius R at (X, Y) in the "
                             "world (repeatable)")
    parser.add_argument("--scenario", default="repeat",
                        help="the scenario to run the movement in "
                             "(default: %(default)s)")
    parser.add_argument("--start-time", type=float, default=None,
                        help="when the movement starts, s (default: the "
                             "scenario's first run's)")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulated time in s (default: the movement's "
                             "length plus the start time and 1.5 s)")
    parser.add_argument("--output", type=Path, default=None,
                        help="output folder (default: out/replay)")
    parser.add_argument("--replay", action="store_true",
                        help="also write the Meshcat replay page")
    add_robot_argument(parser, "play the movement")


def replay_scenario(args):
    """The Scenario that `drake-wbc replay` runs: the repeat scenario
    with one run playing `args.movement` (and the obstacles added),
    described as this replay."""
    from drake_wbc.experiments.scenario import (
        Variant,
        checked_duration,
        find_scenario,
        load_scenario,
    )
    from drake_wbc.math.cdmp import MovementReplay
    from drake_wbc.math.movement import (
        LearnedMovement,
        resolve_movement_file,
        rollout_step,
    )
    from drake_wbc.math.validation import (
        as_vector,
        non_negative,
        positive_duration,
        validate,
        within_site,
    )
    from drake_wbc.station.scene import CylinderObstacle

    if args.duration is not None:
        positive_duration("--duration", args.duration)
    path = find_scenario(args.scenario)
    scenario = on_robot(load_scenario(path), args)
    try:
        file = resolve_movement_file(args.movement).resolve()
    except ValueError as error:  # named as the command line names it
        raise ValueError(f"movement{str(error).removeprefix('file')}"
                         ) from None
    movement = LearnedMovement.load(file)
    base = (scenario.variants[0].movement
            or scenario.controller.whole_body_cdmp.movement
            or MovementReplay(file=str(file)))
    # The options, where they enter: a tau the movement cannot be played
    # at is refused before the run.
    if args.goal is not None:
        as_vector("--goal", args.goal, 4)
        # The goal's position is a point of the scene (1e300 m tripped
        # the controller's safety stop and gave a goal error of inf).
        within_site("--goal", list(args.goal), lengths=args.goal[:3])
    if args.tau is not None:
        rollout_step(movement, args.tau, source=str(file), name="--tau")
    if args.start_time is not None:
        non_negative("--start-time", args.start_time)
    start_time = (base.start_time if args.start_time is None
                  else args.start_time)
    replay = MovementReplay(file=str(file), goal=args.goal, tau=args.tau,
                            start_time=start_time, start=base.start)
    tau = movement.params.tau if args.tau is None else args.tau
    duration = args.duration
    if duration is None:
        duration = (start_time + movement.params.duration * tau
                    / movement.params.tau + 1.5)
        given = ", ".join(
            f"{option} = {value!r}" for option, value in (
                ("--tau", args.tau), ("--start-time", args.start_time))
            if value is not None)
        checked_duration(
            "the movement's run" + (f" ({given})" if given else ""),
            duration, scenario,
            hint="; give a shorter --tau or --start-time, or a --duration")
    else:
        checked_duration("--duration", duration, scenario)
    cylinders = list(scenario.scene.cylinders)
    for i, (x, y, r) in enumerate(args.obstacle or []):
        try:
            cylinders.append(validate(CylinderObstacle(
                name=f"obstacle_{i}", position=[x, y], radius=r,
                height=1.0)))
        except ValueError as error:
            raise ValueError(f"--obstacle {x!r} {y!r} {r!r}: {error}"
                             ) from None
    label = "replay" + (f", goal {list(args.goal)}" if args.goal else "") \
        + (f", tau {args.tau}" if args.tau else "")
    description = (
        f"the robot plays the movement {args.movement} "
        + (f"to the goal {list(args.goal)}" if args.goal else "to its goal")
        + (f" at tau {args.tau:g}" if args.tau is not None else "")
        + "".join(f", past a new pillar of radius {r:g} m at ({x:g}, {y:g})"
                  for x, y, r in args.obstacle or [])
        + f" (in the scene of {path.stem})")
    scenario = replace(
        scenario, description=description, duration=duration,
        scene=replace(scenario.scene, cylinders=cylinders),
        variants=[Variant(name="replay", label=label, movement=replay)])
    return validate(scenario)


def run_replay(args, echo=print):
    """Runs `drake-wbc replay` (see the module's docstring); returns 0."""
    from drake_wbc.experiments.reports import run_scenario, short_run_note

    scenario = replay_scenario(args)
    output = args.output or Path("out") / "replay"
    if echo is not None:
        note = short_run_note(scenario)
        if note is not None:
            print(f"drake-wbc replay {args.movement}: note: {note}",
                  file=sys.stderr, flush=True)
        echo(f"drake-wbc replay {args.movement}: writing to {output}/")
    run_scenario(scenario, output, name="replay", replay=args.replay,
                 progress=echo is not None, echo=echo)
    return 0
