"""The `--robot FILE` option of the commands that run a scenario: the
scenario on the robot of a description YAML
(drake_wbc.experiments.scenario.with_robot), its simulated arm starting
at that robot's home unless it is the scenario's own robot."""

from pathlib import Path


def add_robot_argument(parser, what="run the scenario", why=""):
    """Adds `--robot FILE` to `parser`; `what` starts its help, `why`
    ends it."""
    parser.add_argument(
        "--robot", type=Path, default=None,
        help=f"{what} on the robot of this description YAML (default: the "
             f"scenario's robot, or the shipped one){why}")


def on_robot(scenario, args, echo=print):
    """`scenario` (a Scenario) on the robot of `args.robot`, or itself
    where the command line gives none; `echo` says that the arm starts
    at that robot's home (None for a command whose arm does not start
    there: deploy starts from the measured arm)."""
    robot = getattr(args, "robot", None)
    if robot is None:
        return scenario
    from drake_wbc.experiments.scenario import with_robot

    return with_robot(scenario, robot, echo=echo)
