"""The `drake-wbc` command.

Each subcommand is one entry of `SUBCOMMANDS`: a name, a one-line help, a
function that adds its arguments and a function that runs it and returns
the exit code. Heavy imports happen inside the runners, so that
`drake-wbc --help` answers at once.
"""

import argparse
import os
import re
import sys
from pathlib import Path

from drake_wbc.cli import analysis
from drake_wbc.cli.hardware import PROGRAMS
from drake_wbc.cli.robot_option import add_robot_argument, on_robot


def _add_demo_arguments(parser):
    parser.add_argument(
        "--output",
        type=Path,
        default=Path("out") / "demo",
        help="folder for the Meshcat page (default: %(default)s)",
    )
    parser.add_argument(
        "--q-arm",
        type=float,
        nargs="+",
        metavar="Q",
        help="arm configuration in rad, one a joint (default: the home "
             "pose)",
    )
    parser.add_argument(
        "--robot", type=Path, default=None,
        help="a robot description YAML file (default: the shipped robot, "
             "models/mcr.robot.yaml)")
    parser.add_argument(
        "--controller", type=Path, default=None,
        help="controller parameters YAML whose capability band and k_j to "
             "check on the robot (default: diagrams/controller.yaml's)")


def _checked_q_arm(q_arm, arm):
    """`q_arm` (--q-arm; None: the home pose) checked against the arm of
    `arm`, an ArmKinematics: one finite value a joint, each within its
    joint's limits.

    Raises:
        ValueError: naming --q-arm, and the joint, its value and its
            limits for one outside them.
    """
    if q_arm is None:
        return None
    from drake_wbc.math.validation import as_vector

    q = as_vector("--q-arm", q_arm, arm.num_joints)
    for i, joint in enumerate(arm.model.arm_joints):
        low, high = float(arm.lower[i]), float(arm.upper[i])
        if not low <= q[i] <= high:
            raise ValueError(
                f"--q-arm[{i}] = {float(q[i])!r} rad (joint "
                f"{joint.name()}) is not allowed: must lie within the "
                f"joint's limits [{low!r}, {high!r}] rad")
    return q


def file_stem(name, fallback="robot"):
    """`name` (a robot's, as its description gives it: any text) made fit
    for a file's name on every system: each run of characters other than
    letters, digits, '.', '_' and '-' becomes one '_', leading and
    trailing dots and '_' go, and it is cut to 100 characters; `fallback`
    where nothing is left. "acme/arm v2" gives "acme_arm_v2"."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._")[:100]
    return stem.rstrip("._") or fallback


def _run_demo(args):
    from drake_wbc.cli.model_report import (
        describe_robot,
        describe_self_contacts,
        describe_tuning,
        write_model_page,
    )
    from drake_wbc.controller import load_controller_parameters
    from drake_wbc.controller.parameters import ControllerParameters, for_robot
    from drake_wbc.experiments.scenario import robot_option_file
    from drake_wbc.robot.description import (
        load_robot_description,
        shipped_robot,
    )
    from drake_wbc.robot.model import ArmKinematics, make_robot_plant

    try:
        if args.controller is not None and not args.controller.is_file():
            raise ValueError(
                f"--controller = {str(args.controller)!r} is not allowed: "
                + ("a folder, not a controller parameters file"
                   if args.controller.is_dir() else "no such file"))
        description = (shipped_robot() if args.robot is None
                       else load_robot_description(
                           robot_option_file(args.robot)))
        params = for_robot(
            ControllerParameters() if args.controller is None
            else load_controller_parameters(args.controller), description)
        arm = ArmKinematics(*make_robot_plant(description))
        q_arm = _checked_q_arm(args.q_arm, arm)
        report = describe_robot(
            q_arm, k_j=params.capability.joint_limit_gain,
            description=description)
    except (ValueError, OSError) as error:
        print(f"drake-wbc demo: {error}", file=sys.stderr)
        return 2
    print(f"drake_wbc robot model {description.name!r} "
          f"({args.robot or 'the shipped robot'})\n")
    print(report)
    print()
    print(describe_tuning(arm, params.capability_band,
                          params.capability.joint_limit_gain,
                          params.workspace.workspace))
    page, contacts = write_model_page(
        args.output / f"{file_stem(description.name)}_model.html", q_arm,
        description=description)
    if contacts:
        print(f"\n{describe_self_contacts(contacts)}")
    print(f"\nMeshcat page of the model (open it in a browser): {page}")
    return 0


def _add_run_arguments(parser):
    parser.add_argument(
        "scenario", nargs="?", default=None,
        help="a scenario's name (see --list) or YAML file (default: the "
             "default scenario)")
    parser.add_argument("--list", action="store_true",
                        help="list the scenarios, one line each, and exit")
    parser.add_argument(
        "--output", type=Path, default=None,
        help="output folder (default: out/<scenario>)")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulated time in s (default: the scenario's)")
    parser.add_argument("--no-replay", action="store_true",
                        help="do not write the Meshcat replay pages")
    add_robot_argument(parser)
    parser.add_argument(
        "--sweep", action="store_true",
        help="trajectory-tracking scenarios: run the step over small maps "
             "of base models around the scenario's (velocity loop, "
             "suspension, acceleration limit, wheels' compliance) and "
             "plot the filter's benefit (in <output>/sweep/; a few "
             "minutes)")


def _run_run(args):
    from drake_wbc.experiments.reports import run_scenario, short_run_note
    from drake_wbc.experiments.scenario import (
        DEFAULT_SCENARIO,
        checked_duration,
        find_scenario,
        load_scenario,
        scenario_files,
    )

    if args.list:
        if args.scenario is not None:
            raise ValueError(
                f"scenario = {args.scenario!r} is not allowed with --list, "
                "which lists every scenario: give one or the other")
        paths = scenario_files()
        width = max(len(path.stem) for path in paths)
        for path in paths:
            scenario = load_scenario(path)
            marker = " (default)" if path.stem == DEFAULT_SCENARIO else ""
            print(f"{path.stem:{width}s}  {scenario.description}{marker}")
        return 0
    path = find_scenario(DEFAULT_SCENARIO if args.scenario is None
                         else args.scenario)
    if args.duration is not None:
        from drake_wbc.math.validation import positive_duration

        positive_duration("--duration", args.duration)  # before the load
    output = args.output or Path("out") / path.stem
    scenario = on_robot(load_scenario(path), args)
    if args.duration is not None:
        checked_duration("--duration", args.duration, scenario)
    if args.sweep:
        from drake_wbc.analysis.base_sweep import check_sweep, run_sweep

        if args.duration is not None:
            scenario.duration = args.duration
        try:
            check_sweep(scenario, "--duration" if args.duration is not None
                        else f"duration (of {path.name})")
        except ValueError as error:
            if not str(error).startswith("experiment = "):
                raise
            raise ValueError(
                f"scenario = {path.stem!r} is not allowed with --sweep: "
                "must be a trajectory-tracking scenario with the runs "
                "filtered and unfiltered (e.g. trajectory_tracking)"
            ) from None
        print(f"drake-wbc run {path.stem} --sweep: writing to "
              f"{output / 'sweep'}/", flush=True)
        run_sweep(scenario, output / "sweep",
                  echo=lambda line: print(line, flush=True))
        return 0
    output.mkdir(parents=True, exist_ok=True)  # an error before the note
    note = short_run_note(scenario, args.duration)
    if note is not None:
        print(f"drake-wbc run {path.stem}: note: {note}", file=sys.stderr,
              flush=True)
    print(f"drake-wbc run {path.stem}: writing to {output}/", flush=True)
    run_scenario(scenario, output, name=path.stem, duration=args.duration,
                 replay=False if args.no_replay else None)
    return 0


def _add_bench_arguments(parser):
    from drake_wbc.bench import add_bench_arguments

    add_bench_arguments(parser)


def _run_bench(args):
    from drake_wbc.bench import run_bench

    return run_bench(args)


def _add_teach_arguments(parser):
    from drake_wbc.cli.teach import add_teach_arguments

    add_teach_arguments(parser)


def _run_teach(args):
    from drake_wbc.cli.teach import run_teach

    return run_teach(args)


def _add_replay_arguments(parser):
    from drake_wbc.cli.teach import add_replay_arguments

    add_replay_arguments(parser)


def _run_replay(args):
    from drake_wbc.cli.teach import run_replay

    return run_replay(args)


def _add_stress_arguments(parser):
    from drake_wbc.stress.run import add_stress_arguments

    add_stress_arguments(parser)


def _run_stress(args):
    from drake_wbc.stress.run import run_stress

    return run_stress(args)


SUBCOMMANDS = (
    (
        "run",
        "run a scenario (one of the paper's experiments) in simulation and "
        "write its logs, figures, metrics and Meshcat replay",
        _add_run_arguments,
        _run_run,
    ),
    ("bench", "benchmark the closed-form controller against QP-based "
     "peers (Drake's DiffIK, qpsolvers), a control tick per stage, and each "
     "scenario's real-time factor and memory", _add_bench_arguments,
     _run_bench),
    ("stress", "run N seeded random closed-loop cases (obstacles, people, "
     "hand forces, references) in parallel or on a Dask cluster and check "
     "the safety invariants", _add_stress_arguments, _run_stress),
    ("teach", "run a pHRI scenario (or read an lcm-logger log), record the "
     "demonstration the hand gave and learn it as a whole-body DMP "
     "movement file", _add_teach_arguments, _run_teach),
    ("replay", "play a learned movement through the whole controller in "
     "simulation, to its goal or a moved one, at another tau or past new "
     "obstacles, and plot it against the demonstration",
     _add_replay_arguments, _run_replay),
    ("bode", analysis.BODE_HELP, analysis.add_bode_arguments,
     analysis.run_bode),
    ("diagram", analysis.DIAGRAM_HELP, analysis.add_diagram_arguments,
     analysis.run_diagram),
    *PROGRAMS,
    (
        "demo",
        "load the robot model, print its joints, limits and capability of "
        "movement, and write a Meshcat page of it",
        _add_demo_arguments,
        _run_demo,
    ),
)


_TYPE_NAMES = {"float": "a number", "int": "a whole number",
               "path": "a file or folder name (not empty)"}
"""What an argument of each type (argparse's name of it) must be."""


def plain_error(message):
    """argparse's `message` of a command line it cannot parse, in the
    words of every other error: "argument --duration: invalid float
    value: 'abc'" becomes "--duration = 'abc' is not allowed: must be a
    number"."""
    match = re.fullmatch(r"argument (\S+?)(?:/\S+)?: (.*)", message,
                         re.S)
    if match is None:
        return message
    option, reason = match.groups()
    invalid = re.fullmatch(r"invalid (\w+) value: ('.*')", reason, re.S)
    if invalid is not None and invalid[1] in _TYPE_NAMES:
        return (f"{option} = {invalid[2]} is not allowed: must be "
                f"{_TYPE_NAMES[invalid[1]]}")
    choice = re.fullmatch(r"invalid choice: ('.*?') \(choose from (.*)\)",
                          reason, re.S)
    if choice is not None:
        name = "command" if option == "COMMAND" else option
        return (f"{name} = {choice[1]} is not allowed: must be one of "
                f"{choice[2].replace(chr(39), '')}")
    return f"{option}: {reason}"


class CommandParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line, as every other error
    of the command: the option, its value and what is allowed, then
    where to read more; exit code 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: {plain_error(message)} (see "
                     f"{self.prog} --help)\n")


def path(text):
    """A path argument: any text but an empty one (Path("") is ".", the
    current folder, which an empty --output or --robot never meant)."""
    if not text.strip():
        raise ValueError("an empty name")
    return Path(text)


def _checked_paths(parser):
    """Makes every argument of `parser` read as a Path refuse an empty
    string (`path`)."""
    for action in parser._actions:
        if action.type is Path:
            action.type = path


def make_parser():
    """Returns the argument parser of `drake-wbc`."""
    parser = CommandParser(
        prog="drake-wbc",
        description=(
            "Whole-body control of velocity-controlled mobile collaborative "
            "robots with Coupling Dynamic Movement Primitives (CDMP-WBC), "
            "built on Drake."
        ),
    )
    from drake_wbc import __version__

    parser.add_argument(
        "--version", action="version", version=f"%(prog)s {__version__}"
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, summary, add_arguments, run in SUBCOMMANDS:
        sub = commands.add_parser(name, help=summary, description=summary)
        add_arguments(sub)
        _checked_paths(sub)
        sub.set_defaults(run=run)
    return parser


OUTPUT_OPTIONS = ("output", "movement")
"""The options that name where a command writes (a folder or a file)."""


def _unwritable(args, error):
    """The one-line message of `error`, an OSError a command met, and its
    exit code: 2 naming the option when it met it where an output option
    (`OUTPUT_OPTIONS`) points, in it or on the way to it, 1 otherwise."""
    reason = error.strerror or str(error)
    if error.filename is not None:
        failed = Path(os.fsdecode(error.filename))
        for option in OUTPUT_OPTIONS:
            given = getattr(args, option, None)
            if given is not None and (
                    failed == Path(given) or Path(given) in failed.parents
                    or failed in Path(given).parents):
                return (f"--{option} = {str(given)!r} is not allowed: "
                        f"cannot write {str(failed)!r} ({reason})"), 2
        return f"cannot write {str(failed)!r} ({reason})", 1
    return reason, 1


def main(argv=None):
    """Runs `drake-wbc` with `argv` (the process's arguments if None)."""
    parser = make_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # --help, --version or a parse error
        return done.code
    if args.command is None:
        parser.print_help()
        return 2
    try:
        code = args.run(args)
        sys.stdout.flush()  # a closed pipe is found here, not at exit
        return code
    except ValueError as error:
        print(f"drake-wbc {args.command}: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C: stop without a traceback
        print(f"\ndrake-wbc {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `drake-wbc run --list | head -3`
        # Python would flush stdout again at exit, into the closed pipe.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as error:  # e.g. an --output that cannot be written
        message, code = _unwritable(args, error)
        print(f"drake-wbc {args.command}: {message}", file=sys.stderr)
        return code


if __name__ == "__main__":
    sys.exit(main())
