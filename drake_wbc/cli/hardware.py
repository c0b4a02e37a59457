"""The commands `drake-wbc robot-sim`, `drake-wbc deploy` and
`drake-wbc plot`, as argument adders and runners (each runner returns the
exit code); `drake-wbc` (drake_wbc.cli.main) offers them.

- robot-sim SCENARIO: the simulated station speaking the robot's side of
  the LCM protocol (drake_wbc.deployment.robot_side), paced to the wall
  clock, until its duration or Ctrl-C.
- deploy SCENARIO: the scenario's controller and task against the robot
  over LCM in real time (drake_wbc.deployment.deploy) for the
  scenario's duration; Ctrl-C stops it cleanly: zero base velocity and
  the arm held are sent first. Exit code 0 at the end, 130 when stopped.
- plot LOGFILE: an lcm-logger log as the signals of a run
  (drake_wbc.deployment.lcm_logs), with the scenario's metrics and figures.

The LCM URL and channels are the scenario's `hardware:` (its defaults
when the scenario has none); --lcm-url overrides the URL.
"""

import logging
import math
import signal
import sys
import time
from dataclasses import replace
from pathlib import Path

from drake_wbc.cli.robot_option import add_robot_argument, on_robot

INTERRUPTED = 130
"""The exit code after a stop by SIGINT or SIGTERM."""


class StopRequest:
    """Turns SIGINT and SIGTERM into a flag (restored on exit), so that a
    run stops between two steps instead of inside one."""

    def __init__(self):
        self.requested = False
        self._previous = {}

    def __call__(self):
        return self.requested

    def _handle(self, signum, frame):
        del frame
        self.requested = True
        print(f"\n{signal.Signals(signum).name}: stopping", file=sys.stderr)

    def __enter__(self):
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc):
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        return False


def _log_to_stderr():
    """The drake_wbc.hardware logger's warnings (watchdog, rejected
    messages) on stderr, time-stamped."""
    logger = logging.getLogger("drake_wbc.hardware")
    if not logger.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter(
            "%(asctime)s %(name)s: %(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)


def _scenario_and_options(args, echo=print):
    """The scenario's path, the scenario on --robot and its hardware
    options with --lcm-url; `echo` says where the arm starts on another
    robot (None: the command starts from no arm of its own)."""
    from drake_wbc.experiments.scenario import find_scenario, load_scenario
    from drake_wbc.hardware.options import HardwareOptions
    from drake_wbc.math.validation import validate

    path = find_scenario(args.scenario)
    scenario = load_scenario(path)
    scenario = on_robot(scenario, args, echo)
    options = scenario.hardware or HardwareOptions()
    if args.lcm_url is not None:
        try:
            options = validate(replace(options, lcm_url=args.lcm_url))
        except ValueError as error:  # named as typed
            if not str(error).startswith("lcm_url = "):
                raise
            raise ValueError(
                f"--lcm-url{str(error).removeprefix('lcm_url')}") from None
    return path, scenario, options


def _add_common(parser):
    parser.add_argument(
        "scenario", help="a scenario's name or YAML file (its `hardware:` "
                         "block gives the LCM URL and channels)")
    parser.add_argument(
        "--lcm-url", default=None,
        help="the LCM URL (default: the scenario's, or "
             "udpm://239.255.76.67:7667?ttl=0)")
    add_robot_argument(
        parser, "run", ": its arm's joints size the messages, its own "
                       "limits bound the commands")


def _duration(value, hint="", longest=None):
    """--duration, checked (None: the scenario's): at most `longest` s
    (drake_wbc.math.validation.LONGEST_RUN if None); `hint` ends the
    message of one too long."""
    if value is None:
        return None
    from drake_wbc.math.validation import LONGEST_RUN, positive_duration

    return positive_duration("--duration", value,
                             longest=longest or LONGEST_RUN, hint=hint)


def _realtime_rate(value):
    """--realtime-rate, checked: a positive finite number (0 would run the
    Simulator unpaced, as fast as it can; a negative or NaN rate means
    nothing)."""
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"--realtime-rate = {value!r} is not allowed: must "
                         "be a positive finite number (1 is real time)")
    return value


def add_robot_sim_arguments(parser):
    """`drake-wbc robot-sim`'s arguments."""
    _add_common(parser)
    parser.add_argument(
        "--duration", type=float, default=None,
        help="simulated time in s (default: until Ctrl-C)")
    parser.add_argument(
        "--realtime-rate", type=float, default=1.0,
        help="target real-time rate, > 0 (default: %(default)s)")


def run_robot_sim(args):
    """Runs the simulated robot on LCM; returns the exit code."""
    from pydrake.lcm import DrakeLcm
    from pydrake.systems.analysis import Simulator

    from drake_wbc.deployment.robot_side import RobotSide
    from drake_wbc.experiments.runner import Progress

    _log_to_stderr()
    duration = _duration(args.duration, hint="; leave --duration out to "
                         "run until Ctrl-C")
    rate = _realtime_rate(args.realtime_rate)
    path, scenario, options = _scenario_and_options(args)
    lcm = DrakeLcm(options.lcm_url)
    robot = RobotSide(scenario, options, lcm)
    simulator = Simulator(robot.diagram)
    root = simulator.get_mutable_context()
    robot.set_initial_state(root)
    robot.set_time_offset(root, time.time())
    simulator.set_target_realtime_rate(rate)
    channels = options.channels
    print(f"drake-wbc robot-sim {path.stem} on {options.lcm_url}: sending "
          f"{channels.base_state}, {channels.arm_status}, "
          f"{channels.wrist_wrench}, {channels.obstacle_points}, "
          f"{channels.truth}; listening to {channels.base_command}, "
          f"{channels.arm_command}", flush=True)
    started = time.perf_counter()
    meter = Progress(f"robot-sim {path.stem}", duration)
    with StopRequest() as stop:
        simulator.Initialize()
        t = 0.0
        while (duration is None or t < duration - 1e-12) and not stop():
            t = t + 0.05 if duration is None else min(t + 0.05, duration)
            simulator.AdvanceTo(t)
            if duration is None or t < duration - 1e-12:
                meter.update(t)
    meter.update(root.get_time(), done=True)
    elapsed = time.perf_counter() - started
    print(f"robot-sim: {root.get_time():.2f} s simulated in {elapsed:.2f} s "
          f"(real-time factor {root.get_time() / max(elapsed, 1e-9):.2f})",
          flush=True)
    return INTERRUPTED if stop.requested else 0


def add_deploy_arguments(parser):
    """`drake-wbc deploy`'s arguments."""
    _add_common(parser)
    parser.add_argument(
        "--variant", default=None,
        help="the scenario's run to deploy (default: its first)")
    parser.add_argument(
        "--duration", type=float, default=None,
        help="controller time in s, at most a day (default: the "
             "scenario's)")
    parser.add_argument(
        "--realtime-rate", type=float, default=1.0,
        help="target real-time rate, > 0 (default: %(default)s; below 1 "
             "only against a simulated robot run at the same rate)")


def run_deploy(args):
    """Runs the controller against the robot over LCM; returns the exit
    code."""
    import numpy as np

    from drake_wbc.deployment.deploy import LONGEST_DEPLOYMENT, deploy
    from drake_wbc.experiments.runner import Progress

    _log_to_stderr()
    duration = _duration(args.duration, longest=LONGEST_DEPLOYMENT)
    rate = _realtime_rate(args.realtime_rate)
    # The controller starts from the measured arm, not from a home.
    path, scenario, options = _scenario_and_options(args, echo=None)
    variant = _variant(scenario, args.variant)
    channels = options.channels
    print(f"drake-wbc deploy {path.stem} ({variant.name}) on "
          f"{options.lcm_url}: waiting for {channels.base_state}, "
          f"{channels.arm_status}, {channels.wrist_wrench} and "
          f"{channels.obstacle_points}", flush=True)
    meter = []  # the run's progress line, from the controller's start

    def started(arm_positions):
        print("deploy: running from the arm at "
              f"{np.array2string(arm_positions, precision=3)} rad (Ctrl-C "
              "stops the robot)", flush=True)
        meter.append(Progress(f"deploy {variant.name}",
                              duration or scenario.duration, what="run"))

    with StopRequest() as stop:
        try:
            result = deploy(
                scenario, variant, options, duration=duration, stop=stop,
                realtime_rate=rate, on_start=started,
                on_progress=lambda t: meter[0].update(t))
        except TimeoutError as error:
            print(f"drake-wbc deploy: {error}", file=sys.stderr)
            return 1
    if result is None:
        print("deploy: stopped before the robot answered", flush=True)
        return INTERRUPTED
    meter[0].update(result.time, done=True)
    diagnostics = ", ".join(f"{k} {v:g}" for k, v in
                            result.diagnostics.items()
                            if not k.endswith("_age"))
    print(f"deploy: {'stopped' if result.stopped else 'finished'} at "
          f"t = {result.time:.2f} s (real-time factor "
          f"{result.real_time_factor:.2f}); sent zero base velocity and "
          f"held the arm; {diagnostics}", flush=True)
    return INTERRUPTED if result.stopped else 0


def _variant(scenario, name):
    if name is None:
        return scenario.variants[0]
    for variant in scenario.variants:
        if variant.name == name:
            return variant
    names = ", ".join(v.name for v in scenario.variants)
    raise ValueError(f"--variant = {name!r} is not allowed: must be one of "
                     f"{names}")


def add_plot_arguments(parser):
    """`drake-wbc plot`'s arguments."""
    parser.add_argument("logfile", type=Path,
                        help="an LCM log (lcm-logger's)")
    parser.add_argument(
        "--scenario", default=None,
        help="the scenario that ran (its experiment's metrics and figures, "
             "and its channels; default: the overview figure only)")
    parser.add_argument("--variant", default=None,
                        help="the scenario's run that was deployed (default: "
                             "its first)")
    parser.add_argument("--output", type=Path, default=None,
                        help="output folder (default: out/<logfile's name>)")
    parser.add_argument(
        "--deployment", type=int, default=0,
        help="which deployment when the log holds several (0: the first, "
             "-1: the last)")
    add_robot_argument(
        parser, "compute the metrics",
        ": the robot that ran, as deploy's --robot gave it")


def run_plot(args):
    """Writes the figures, log and summary of an LCM log; returns the exit
    code."""
    from drake_wbc.deployment.plots import plot_lcm_log
    from drake_wbc.experiments.reports import json_text

    if not args.logfile.is_file():
        raise ValueError(f"logfile = {str(args.logfile)!r} is not allowed: "
                         + ("a folder, not an LCM log"
                            if args.logfile.is_dir() else "no such file"))
    output = args.output or Path("out") / args.logfile.stem
    scenario = args.scenario
    if args.robot is not None:
        from drake_wbc.experiments.scenario import (
            Scenario,
            find_scenario,
            load_scenario,
        )

        scenario = on_robot(
            Scenario(description=f"LCM log {args.logfile.stem}")
            if scenario is None else load_scenario(find_scenario(scenario)),
            args, echo=None)  # a log's arm started where it was
    try:
        summary = plot_lcm_log(args.logfile, output, scenario=scenario,
                               variant=args.variant,
                               deployment=args.deployment)
    except ValueError as error:  # the options' errors, named as typed
        if str(error).startswith(("variant = ", "deployment = ")):
            raise ValueError(f"--{error}") from None
        if str(error).startswith("path = "):  # the log file's
            raise ValueError(
                f"logfile{str(error).removeprefix('path')}") from None
        raise
    print(json_text({k: v for k, v in summary.items() if k != "runs"}))
    print(f"Written to {output}/: "
          f"{', '.join(summary['files'] + ['summary.json'])}")
    return 0


PROGRAMS = (
    ("robot-sim", "run the simulated robot on LCM (the robot's side of the "
     "protocol), paced to the wall clock", add_robot_sim_arguments,
     run_robot_sim),
    ("deploy", "run a scenario's controller against the robot over LCM in "
     "real time", add_deploy_arguments, run_deploy),
    ("plot", "the metrics and figures of an LCM log of a run",
     add_plot_arguments, run_plot),
)
"""(name, help, add arguments, run) of each command."""
