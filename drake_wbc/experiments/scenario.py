"""Scenarios: one experiment, written as a YAML file in diagrams/.

A scenario says everything a run needs: the controller's parameters, how
the simulated station is built, the scene (obstacles, walking people, a
hand on the tool), the task's inputs over time, the duration, the runs to
compare and what to write. It is loaded with Drake's `yaml_load_typed`
into the dataclasses below, then every check of the tree runs, so a wrong
key or value is reported with the file, the field's dotted path and what
is allowed (drake_wbc.math.loading.load_typed, which also refuses
files written to hurt the loader: aliases that multiply, deep nesting,
duplicate keys, text that is not UTF-8)::

    description: the end effector holds still while a person walks by
    experiment: fixed_point
    duration: 20.0
    controller:                       # ControllerParameters; keys left
      distributor: {null_space_gain: 0.1}   # out keep their defaults
    scene:
      people:
      - {name: visitor, times: [2, 6], waypoints: [[2, -1], [0.5, -1]]}
    task:
      reference_velocity: {times: [1.0], values: [[0.1, 0, 0, 0, 0, 0]]}

The files are in diagrams/ (`scenarios_dir()`); `find_scenario` takes a
file's path or its name without `.yaml`.
"""

import copy
import warnings
from dataclasses import dataclass, field, fields
from pathlib import Path

from drake_wbc.controller import ControllerParameters
from drake_wbc.controller.diagram import tuning_problems
from drake_wbc.controller.parameters import for_robot
from drake_wbc.controller.task import TaskInputs
from drake_wbc.hardware.options import HardwareOptions, command_timeout_of
from drake_wbc.math.cdmp import MovementReplay
from drake_wbc.math.loading import load_typed, screened_data
from drake_wbc.math.validation import (
    boolean,
    checked_instance,
    positive,
    positive_duration,
    text,
)
from drake_wbc.robot.description import (
    SHIPPED_ROBOT_FILE,
    load_robot_description,
    models_dir,
    shipped_robot,
)
from drake_wbc.robot.footprint import check_start_is_free
from drake_wbc.robot.model import ArmKinematics, ArmMount, shared_robot_plant
from drake_wbc.robot.tuning import RobotTuningWarning
from drake_wbc.station.drivers import (
    check_base_time_step,
    moved_base_loop,
    own_base_loop,
)
from drake_wbc.station.scene import Scene
from drake_wbc.station.simulation import (
    SimulatedStation,
    StationOptions,
    check_arm_start,
)
from drake_wbc.station.traction import own_traction

EXPERIMENTS = ("generic", "trajectory_tracking", "fixed_point",
               "line_tracking", "wiping", "phri", "teach", "repeat")
"""The experiments whose metrics and plots a run computes (paper Sec. V);
`generic` gives the common ones only."""

CONTROLLER_FILE = "controller.yaml"
"""The file in diagrams/ that holds the controller's defaults, not a
scenario."""

DEFAULT_SCENARIO = "trajectory_tracking"
"""The scenario `drake-wbc run` runs when given none."""


@dataclass
class Variant:
    """One run of a scenario; several are compared in one figure.

    Attributes:
        name: a short name, used in file names (letters, digits, _ and -).
        label: the legend's text (the name if empty).
        base_filter: False runs without the base filter (the paper's
            comparison in the trajectory-tracking experiment).
        movement: the learned movement this run plays, replacing the
            controller's whole_body_cdmp.movement (None: the
            controller's).
    """

    name: str = "run"
    label: str = ""
    base_filter: bool = True
    movement: MovementReplay | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name or not all(
                c.isalnum() or c in "_-" for c in self.name):
            raise ValueError(
                f"name = {self.name!r} is not allowed: must be letters, "
                "digits, _ and - only, and not empty")
        text("label", self.label)
        boolean("base_filter", self.base_filter)
        self.movement = checked_instance("movement", self.movement,
                                         MovementReplay, lambda: None)


@dataclass
class OutputOptions:
    """What a run writes.

    Attributes:
        log_period: the logs' sample period in s (the control period by
            default).
        replay: write the Meshcat replay (replay.html).
        replay_frame_rate: the replay's frames per second.
        plots: write the PNG figures.
    """

    log_period: float = 0.01
    replay: bool = True
    replay_frame_rate: float = 25.0
    plots: bool = True

    def __post_init__(self):
        positive("log_period", self.log_period)
        positive("replay_frame_rate", self.replay_frame_rate)
        boolean("replay", self.replay)
        boolean("plots", self.plots)


@dataclass
class Scenario:
    """One experiment (see the module's docstring).

    Attributes:
        description: one line, shown by `drake-wbc run --list`.
        experiment: one of EXPERIMENTS: which metrics and plots a run
            computes.
        duration: simulated time in s.
        controller: the controller's parameters (defaults: the paper's).
        station: how the simulated station is built.
        robot: the robot's description file (drake_wbc.robot.description;
            relative to the scenario's folder), or "" for the shipped
            robot. The controller, the simulated station and the LCM
            interface take it; station.initial_arm_positions gives the
            start of its arm (its home where left out).
        arm_mount: the robot's arm mount (drake_wbc.robot.model.ArmMount:
            the arm's rotation about the base's vertical and its tilt),
            which the simulated station builds and the controller's
            kinematics take (R_ba); the shipped robot's (none) by
            default: it poses the weld of the robot's model directives
            whose child is the description's arm.base_frame.
        scene: obstacles, people and the hand.
        task: the task inputs over time.
        variants: the runs to compare (one run if a single entry).
        outputs: what to write.
        hardware: the LCM hardware interface (URL, channels, watchdog) for
            `drake-wbc deploy` and `drake-wbc robot-sim`; None (the
            default) runs the simulated station only.

    Besides each part's own checks: controller.time_step is a whole
    multiple of station.time_step and equals station.arm.command_period
    (and hardware.publish_period, with hardware), outputs.log_period is
    at least station.time_step and outputs.replay_frame_rate at most its
    inverse, and no static obstacle overlaps the base's footprint at
    station.initial_base_pose.
    """

    description: str = ""
    experiment: str = "generic"
    duration: float = 10.0
    controller: ControllerParameters = field(
        default_factory=ControllerParameters)
    station: StationOptions = field(default_factory=StationOptions)
    arm_mount: ArmMount = field(default_factory=ArmMount)
    robot: str = ""
    scene: Scene = field(default_factory=Scene)
    task: TaskInputs = field(default_factory=TaskInputs)
    variants: list[Variant] = field(default_factory=lambda: [Variant()])
    outputs: OutputOptions = field(default_factory=OutputOptions)
    hardware: HardwareOptions | None = None

    def __post_init__(self):
        text("description", self.description)
        text("robot", self.robot)
        for item in fields(self):
            kind = _PARTS.get(item.name)
            if kind is not None:
                setattr(self, item.name, checked_instance(
                    item.name, getattr(self, item.name), kind, kind))
        if self.experiment not in EXPERIMENTS:
            raise ValueError(
                f"experiment = {self.experiment!r} is not allowed: must be "
                f"one of {', '.join(EXPERIMENTS)}")
        positive("duration", self.duration)
        checked_duration("duration", self.duration, self)
        if not self.variants:
            raise ValueError("variants = [] is not allowed: give at least "
                             "one run")
        names = [v.name for v in self.variants]
        if len(set(names)) != len(names):
            raise ValueError(f"variants = {names} is not allowed: the "
                             "names must differ")
        ratio = self.controller.time_step / self.station.time_step
        if abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(
                f"controller.time_step = {self.controller.time_step!r} s is "
                f"not allowed with station.time_step = "
                f"{self.station.time_step!r} s: must be a whole multiple "
                "of it")
        command_period = self.station.arm.command_period
        if abs(command_period - self.controller.time_step) > 1e-9:
            raise ValueError(
                f"station.arm.command_period = {command_period!r} s is not "
                f"allowed with controller.time_step = "
                f"{self.controller.time_step!r} s: the arm's driver must "
                "sample the position command at the control period (it "
                "moves to each command over one period)")
        period = (None if self.hardware is None
                  else self.hardware.publish_period)
        if period is not None and abs(
                period - self.controller.time_step) > 1e-9:
            raise ValueError(
                f"hardware.publish_period = {self.hardware.publish_period!r}"
                f" s is not allowed with controller.time_step = "
                f"{self.controller.time_step!r} s: the controller sends its "
                "commands once a tick, so the two must be equal")
        scan = self.controller.safety.people.scan_period
        lidar = 1.0 / self.station.lidar.rate
        if scan < lidar - 1e-12:
            raise ValueError(
                f"controller.safety.people.scan_period = {scan!r} s is not "
                f"allowed with station.lidar.rate = "
                f"{self.station.lidar.rate!r} Hz: must be at least the "
                f"LIDARs' period {lidar:.6g} s (a person is seen up to a "
                "scan late; a shorter period shrinks the separation kept)")
        step = self.station.time_step
        if self.outputs.log_period < step:
            raise ValueError(
                f"outputs.log_period = {self.outputs.log_period!r} s is not "
                f"allowed with station.time_step = {step!r} s: must be at "
                "least the station's step (the logged signals change once a "
                "step; a shorter period repeats them and fills the memory)")
        if self.outputs.replay_frame_rate > 1.0 / step:
            raise ValueError(
                f"outputs.replay_frame_rate = "
                f"{self.outputs.replay_frame_rate!r} Hz is not allowed with "
                f"station.time_step = {step!r} s: must be at most 1 / "
                f"station.time_step = {1.0 / step:.6g} Hz (the scene moves "
                "once a step; more frames repeat it and fill the memory)")
        if not self.robot:  # another robot's: where its file is loaded
            check_on_robot(self)


def checked_duration(name, value, scenario, hint=""):
    """`value`, a run's length in s for `scenario` (its `duration`, a
    command's --duration), checked: finite, > 0, at most
    drake_wbc.math.validation.LONGEST_RUN, and at least the scenario's
    outputs.log_period (a shorter run logs its start alone, and every
    metric needs two samples). `hint` ends the message of one too long.

    Raises:
        ValueError: naming `name`, its value and what is allowed.
    """
    number = positive_duration(name, value, hint=hint)
    period = scenario.outputs.log_period
    if number < period - 1e-12:
        raise ValueError(
            f"{name} = {number!r} is not allowed: must be at least the "
            f"scenario's outputs.log_period, {period:g} s (a shorter run "
            "logs its start alone)")
    return number


def controller_for(scenario, variant=None):
    """The controller's parameters for one run of `scenario`: a copy of
    scenario.controller on its robot (the robot's own limits and
    footprint where the scenario gives none,
    drake_wbc.controller.parameters.for_robot) with the `variant`'s base
    filter switch and learned movement (None: scenario.controller's)."""
    params = for_robot(copy.deepcopy(scenario.controller),
                       scenario_robot(scenario))
    if variant is not None:
        params.base_filter.enabled = variant.base_filter
        if variant.movement is not None:
            params.whole_body_cdmp.movement = variant.movement
    return params


def footprint_of(scenario):
    """The half sizes (a, b) in m of the footprint of `scenario`'s base
    (its robot's description)."""
    return tuple(scenario_robot(scenario).base.footprint_half_sizes)


def scenario_robot(scenario):
    """The RobotDescription of `scenario`'s robot (its `robot` file, the
    shipped robot if "")."""
    if not scenario.robot:
        return shipped_robot()
    return load_robot_description(scenario.robot)


def scenario_station(scenario):
    """The SimulatedStation of `scenario`: its station options and scene,
    its robot (`scenario_robot`) on its arm mount."""
    return SimulatedStation(scenario.station, scenario.scene,
                            scenario.arm_mount, scenario_robot(scenario))


def station_base(scenario):
    """The simulated base's velocity loop of `scenario`
    (BaseDriverParameters): station.base, or its robot's own where it
    gives none, as the station builds it."""
    return scenario.station.base or own_base_loop(
        scenario_robot(scenario).base)


def controller_arm(scenario):
    """The controller's ArmKinematics for `scenario`'s robot on its
    arm_mount (on the plant shared_robot_plant shares: the shipped robot
    on the shipped mount shares the controller's own)."""
    mount = scenario.arm_mount
    return ArmKinematics(*shared_robot_plant(
        scenario_robot(scenario), mount=None if mount.is_identity else mount))


def robot_option_file(robot_file):
    """`robot_file`, a command line's --robot, as a Path.

    Raises:
        ValueError: naming --robot and its value when it is no file.
    """
    path = Path(robot_file)
    if not path.is_file():
        raise ValueError(
            f"--robot = {str(robot_file)!r} is not allowed: "
            + ("a folder, not a robot description file" if path.is_dir()
               else "no such file"))
    return path


def robot_file_of(scenario):
    """The resolved Path of `scenario`'s robot description file (the
    shipped robot's, models/mcr.robot.yaml, where it names none)."""
    return Path(scenario.robot or models_dir() / SHIPPED_ROBOT_FILE
                ).resolve()


def with_robot(scenario, robot_file, echo=print):
    """A copy of `scenario` on the robot of the description `robot_file`
    (a command line's --robot), its start checked against that robot.

    A start is a configuration of one arm: the same joint angles put
    another arm in another pose (the shipped arm's home stretches a
    longer arm's tool out of its local workspace). So on a robot other
    than the scenario's own (another description file) the arm starts at
    that robot's home, said through `echo`, and a station.base keeps
    what it sets apart from its own robot's loop, the rest that robot's
    (drake_wbc.station.drivers.moved_base_loop); on the scenario's own
    robot it keeps the scenario's start and base.

    Raises:
        ValueError: naming --robot when its file does not exist, the file
            and the field of a description that does not load, or a
            start outside the robot's limits.
    """
    robot_file = robot_option_file(robot_file).resolve()
    description = load_robot_description(robot_file)
    scenario = copy.deepcopy(scenario)
    own, own_base = robot_file_of(scenario), scenario_robot(scenario).base
    scenario.robot = str(robot_file)
    if robot_file != own:
        scenario.station.initial_arm_positions = list(description.arm.home)
        if scenario.station.base is not None:
            try:
                scenario.station.base = checked_base(
                    scenario, moved_base_loop(
                        scenario.station.base, own_base, description.base,
                        "station.base."))
            except ValueError as error:
                raise ValueError(f"--robot = {str(robot_file)!r}: "
                                 f"{error}") from None
        if echo is not None:
            echo(f"the arm starts at {description.name}'s home "
                 f"{list(description.arm.home)} (the scenario's start is "
                 f"for its own robot, {own.name})")
    check_on_robot(scenario)
    if robot_file != own:
        warn_of_the_tuning_at_the_start(scenario)
    return scenario


def checked_base(scenario, base):
    """`base` (BaseDriverParameters), a loop that `scenario`'s
    station.base becomes on its robot, checked against the station's
    step as StationOptions checks a loop given in full.

    Raises:
        ValueError: naming station.time_step and station.base's lag.
    """
    check_base_time_step(base, "station.time_step",
                         scenario.station.time_step, prefix="station.base.")
    return base


def check_on_robot(scenario):
    """Checks the scenario against its robot: the base's footprint free
    of the scene's static obstacles at station.initial_base_pose, the
    wheels' lever of station.traction given by it or by the robot,
    station.initial_arm_positions one value a joint, within its limits,
    and the hardware's timeouts within the robot's own
    (drake_wbc.hardware.options.command_timeout_of), the controller's
    parameters on it (drake_wbc.controller.parameters.for_robot: limits
    that only tighten the robot's, a people tracking that covers a
    walker at its speed); a start left out (None) is the robot's home,
    which its description checks."""
    base = scenario_robot(scenario).base
    try:
        for_robot(scenario.controller, scenario_robot(scenario))
    except ValueError as error:
        raise ValueError(f"controller.{error}") from None
    check_start_is_free(scenario.scene, scenario.station.initial_base_pose,
                        base)
    if scenario.station.traction is not None:
        own_traction(scenario.station.traction, base,
                     prefix="station.traction.")
    if scenario.hardware is not None:
        try:
            command_timeout_of(scenario.hardware, base)
        except ValueError as error:
            raise ValueError(f"hardware.{error}") from None
    if scenario.station.initial_arm_positions is None:
        return
    limits = shared_robot_plant(scenario_robot(scenario))[1].limits
    check_arm_start(scenario.station.initial_arm_positions, limits.lower,
                    limits.upper, "station.initial_arm_positions")


def warn_of_the_tuning_at_the_start(scenario):
    """Warns (RobotTuningWarning) of what the controller's tuning does at
    `scenario`'s start, where it is not its robot's home (build_controller
    checks the home): a capability band active there, the tool beyond
    d^l there in the intuitive pHRI mode, a singular start."""
    start = scenario.station.initial_arm_positions
    if start is None or list(start) == list(
            scenario_robot(scenario).arm.home):
        return
    for problem in tuning_problems(controller_for(scenario),
                                   controller_arm(scenario), start=start):
        warnings.warn(problem, RobotTuningWarning, stacklevel=3)


_PARTS = dict(controller=ControllerParameters, station=StationOptions,
              arm_mount=ArmMount, scene=Scene, task=TaskInputs,
              outputs=OutputOptions)
"""The nested parameters of a Scenario and their types."""


def scenarios_dir():
    """The folder of the scenario files (diagrams/ of the repository, or
    of the installed package)."""
    here = Path(__file__).resolve().parents[1]  # the package
    for candidate in (here / "diagrams", here.parent / "diagrams"):
        if (candidate / CONTROLLER_FILE).is_file():
            return candidate
    raise FileNotFoundError(
        f"the scenario folder was not found next to {here}: expected "
        f"diagrams/{CONTROLLER_FILE} in the package or in the repository")


def scenario_files():
    """The scenario files in diagrams/, sorted by name."""
    return sorted(p for p in scenarios_dir().glob("*.yaml")
                  if p.name != CONTROLLER_FILE)


def find_scenario(name_or_path):
    """The path of a scenario given as a file or a name in diagrams/.

    Raises:
        ValueError: naming the scenario and the names available.
    """
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") and path.is_file():
        return path
    candidate = scenarios_dir() / f"{name_or_path}.yaml"
    if candidate.is_file() and candidate.name != CONTROLLER_FILE:
        return candidate
    names = ", ".join(p.stem for p in scenario_files())
    raise ValueError(f"scenario = {str(name_or_path)!r} is not allowed: "
                     f"must be a scenario file or one of {names}")


def load_scenario(path=None, text=None):
    """A Scenario from a YAML file or string, every field checked; a
    station.initial_arm_positions left out is its robot's home, and the
    fields a station.base leaves out are its robot's own loop's
    (drake_wbc.station.drivers.own_base_loop).

    Raises:
        ValueError: naming the file, the field's dotted path (e.g.
            `scene.people[0].radius`), its value and what is allowed.
    """
    scenario = load_typed(Scenario, path=path, text=text)
    if scenario.robot and path is not None:
        # Relative to the scenario's folder, and checked here, where it
        # enters.
        scenario.robot = str((Path(path).resolve().parent
                              / scenario.robot).resolve())
    try:
        robot = scenario_robot(scenario)
    except (OSError, ValueError) as error:
        raise ValueError(f"{path or 'text'}: robot = "
                         f"{scenario.robot!r}: {error}") from None
    if scenario.station.initial_arm_positions is None:
        scenario.station.initial_arm_positions = list(robot.arm.home)
    if scenario.station.base is not None:
        # Given in part, the fields left out are the robot's own loop's,
        # not BaseDriverParameters' defaults (the shipped base's).
        base = scenario.station.base
        written = screened_data(path=path, text=text)["station"]["base"]
        try:
            scenario.station.base = checked_base(scenario, own_base_loop(
                robot.base, {name: getattr(base, name)
                             for name in written or {}}, "station.base."))
        except ValueError as error:
            raise ValueError(f"{path or 'text'}: {error}") from None
    if scenario.robot:
        try:
            check_on_robot(scenario)
        except ValueError as error:
            raise ValueError(f"{path or 'text'}: {error}") from None
    warn_of_the_tuning_at_the_start(scenario)
    return scenario


def scenario_text(scenario):
    """The YAML text of `scenario`, every field written out: load_scenario
    reads it back as the same scenario (a random stress case's, written
    to be run again with `drake-wbc run`)."""
    from pydrake.common.yaml import yaml_dump_typed

    return yaml_dump_typed(scenario)
