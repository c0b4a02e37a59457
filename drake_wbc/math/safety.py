"""Run-time safety of the controller, as plain math.

The controller (drake_wbc.controller.diagram) must never send a command it
cannot
stand behind. Three mechanisms serve that, and this module holds their math
(numpy only; the Drake systems in drake_wbc.stages.safety are thin over
it):

1. Input validity (`check_vector`, `check_inputs`, `check_points`,
   `check_following`): every
   value that enters the controller is checked once a tick. A NaN, an
   infinite value, a value outside the range a stage accepts (k_n < 0
   in eq. (wbccm), s_c outside [0, 1] in eq. (compensation)) or a switch
   other than 0 or 1 (S_hri) is a fault of that input, and so is a
   measurement that does not follow the command it measures (the arm's
   measured position farther than `arm_follow_tolerance` from the arm
   controller's last position command: the arm stopped on its own, or
   is held). Obstacle points
   are the exception: a row with a NaN or infinite coordinate is dropped
   and counted, not a fault (see `check_points`). `check_inputs` and
   `check_points` have each a float kernel for the control tick
   (`check_inputs_float`, `check_points_float`, drake_wbc.math.kernels;
   the points' in a loop compiled to machine code,
   drake_wbc.math.compiled).
2. The safe stop (`next_stop_state`): on a fault the controller stops (zero
   base velocity, the arm braked to rest within its acceleration limit,
   the DMPs' couplings held; drake_wbc.controller.diagram) and it resumes,
   from what it last sent, only after every input has been valid again
   for `hold_time`; an arm farther than `arm_follow_tolerance` from its
   held command has the command go to where it is during the stop
   (drake_wbc.stages.arm_control), or restart there when the stop
   clears first (`restart_position`).
3. Command limits that keep the direction, in drake_wbc.math.command_limits:
   the base command is scaled as a whole to the robot's velocity limits
   (SafetyParameters, below), and its change from one tick to the next as
   a whole to the acceleration limits.

The robot's limits are its own, from its description
(drake_wbc.robot.description: the base's velocity and acceleration
limits). SafetyParameters may tighten them, not widen them
(`check_within_robot`, when the controller is built); where they give
none, the robot's own hold.
"""

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import NamedTuple

import numpy as np

from drake_wbc.math import kernels
from drake_wbc.math.base_state import BASE_AXES
from drake_wbc.math.compiled import compiled
from drake_wbc.math.scalar_support import all_finite, value_of
from drake_wbc.math.separation import PeopleSeparationParameters
from drake_wbc.math.validation import non_negative, positive, positive_vector

DEFAULT_HOLD_TIME = 0.5
"""Seconds for which every input must be valid again before the controller
resumes after a safe stop.

0.5 s is longer than a transient glitch of a sensor or of a link (a few
dropped or corrupted samples at 100 Hz), long enough for the base's
velocity loop (0.1 to 0.3 s lag) to have come to rest after the stop, and
short enough not to be a nuisance when an operator clears a fault."""

DEFAULT_STOP_DISTANCE = 0.1
"""m: the distance the base keeps from an obstacle point by default."""

TIME_TOLERANCE = 1e-9
"""Rounding allowance (s) when the valid time is compared to the hold
time."""

MEASURED_POSITION_MARGIN = 0.1
"""rad: how far beyond its joints' position limits an arm's measured
position may read before the controller takes it for a fault (a
corrupted or forged status): the encoders of a joint held at its limit
read a little past it, and no arm reads 0.1 rad past it."""


MAX_ODOMETRY = 1e6
"""m and rad: the largest magnitude of the base's odometry pose [x, y,
yaw] that the controller takes as a measurement. An odometry of a
thousand kilometres, or of 160,000 turns, is no robot's: it is a
corrupted or forged state, whose yaw turns the world-frame reference
into an arbitrary direction (sin and cos of 1e30 rad are noise) and
whose position leaves the people tracker no precision to track with."""

MEASURED_TWIST_FACTOR = 10.0
"""How many times the base's own velocity limits its measured twist may
read before the controller takes it for a fault: a pushed base or a
slipping wheel reads beyond its command limit, no omnidirectional base
reads ten times it (a forged 50 m/s)."""


DEFAULT_ARM_FOLLOW_TOLERANCE = 0.1
"""rad: how far a joint's measured position may be from the arm
controller's last position command before the controller takes it that
the arm does not follow (SafetyParameters.arm_follow_tolerance).

Measured over every shipped scenario's full run (`drake-wbc run NAME`,
every variant; the measurement and the command logged at the same tick,
as the InputGuard compares them): the largest |q_cmd - q_meas| of any
joint is 0.0229 rad (repeat_obstacle, a joint of the paper's arm at its
speed limit of 1.57 rad/s: the servo's lag of some 15 ms), 0.0227 in
fixed_point, at most 0.011 in the others (0.0081 on the seven-joint
arm, 0.0066 on the UR-class arm, whose joints move at no more than 0.1
rad/s there). Over LCM the measurement may be as old as the arm_status
watchdog allows (30 ms: 1.57 rad/s x 0.03 s = 0.047 rad more, 0.07 rad
in all). For that arm, 0.1 rad is 4.4 times the largest measured, 1.4
times that worst case over LCM, and it is the arm's own braking
distance from full speed within its acceleration limit (1.57^2 / (2 x
12.56) = 0.098 rad, 5 cm at a tool 0.5 m out): a resume from a command
within it (as from what was last sent, kept) asks the servo for no
more than a step of that size. Such an arm that stops on its own while
its command runs at full speed trips within 64 ms.

It is sized for that arm's joints, and the floor of every arm's
(`arm_follow_tolerance_of`): the other shipped arms' faster joints (the
seven-joint arm's last four at 2.27 to 3.14 rad/s, every UR-class joint
at 3.14 rad/s) lag by more at their full speed, 0.047 rad through the
servo at 3.14 rad/s and 0.14 rad over LCM with a status at the
watchdog's age."""

FOLLOW_TIME = 0.063
"""s: how long behind its command a following arm's measured joint may
be, with margin: the servo's lag (some 15 ms in the shipped scenarios)
and a status as old as the arm_status watchdog allows over LCM (30 ms),
times 1.4. A joint at its full speed is that far behind
(`arm_follow_tolerance_of`)."""


def arm_follow_tolerance_of(joint_speeds):
    """The arm-follow tolerance of an arm whose joints move at most at
    `joint_speeds` (rad/s, its own speed limits), rad: what its fastest
    joint travels in FOLLOW_TIME, at least DEFAULT_ARM_FOLLOW_TOLERANCE
    (0.1 rad for the paper's arm's 1.57 rad/s, 0.198 for the UR-class and
    seven-joint arms' 3.14 rad/s). What SafetyParameters'
    arm_follow_tolerance is on a robot where it gives none."""
    fastest = float(np.max(np.asarray(joint_speeds, dtype=float)))
    return max(DEFAULT_ARM_FOLLOW_TOLERANCE, FOLLOW_TIME * fastest)


class Reason(IntEnum):
    """Why an input is not valid (the reason code of the safety status)."""

    VALID = 0
    NOT_A_NUMBER = 1
    INFINITE = 2
    OUT_OF_RANGE = 3
    MALFORMED = 4
    NOT_A_SWITCH = 5
    NOT_FOLLOWING = 6


class InputCheck(NamedTuple):
    """The result of checking one input.

    Attributes:
        reason: a Reason; VALID when the input is usable.
        entry: the index of the first bad entry (-1 when valid or when the
            whole value is malformed).
        value: the bad entry's value (NaN when valid or malformed); for
            NOT_FOLLOWING its deviation from the command it follows
            (input - command).
    """

    reason: Reason
    entry: int = -1
    value: float = math.nan

    @property
    def valid(self):
        return self.reason is Reason.VALID


VALID = InputCheck(Reason.VALID)
"""The result of checking a valid input."""


@dataclass
class SafetyParameters:
    """Parameters of the controller's run-time safety.

    Attributes:
        hold_time: s > 0 for which every input must be valid again before
            the controller resumes after a safe stop (`DEFAULT_HOLD_TIME`).
        base_velocity_limits: (3,) > 0, the base command's limits
            [vx, vy, wz] in m/s, m/s, rad/s, which may tighten the
            robot's own but not widen them (`check_within_robot`); None
            (the default): the robot's own, from its description, filled
            in when the controller is built
            (drake_wbc.controller.parameters.for_robot).
        base_acceleration_limits: (3,) > 0, the limits of the command's
            rate of change [vx, vy, wz] in m/s^2, m/s^2, rad/s^2;
            likewise.
        stop_distance: m >= 0 that the base keeps from an obstacle point
            (DEFAULT_STOP_DISTANCE). Any value is safe: the rule's own
            braking term (drake_wbc.math.separation, eq. (allowed)) holds
            the base's approach to what its limits and lag can stop from,
            so no stop distance of the robot's needs adding to it.
        stop_time: s > 0, the time constant of the base's approach
            (drake_wbc.math.separation), 0.5 s by default. These two are
            the rule of every obstacle point that is not a moving
            person.
        base_lag: s >= 0, the base's velocity loop lag that the
            separation rules' stop allows for (eqs. (allowed),
            (protective)); None (the default): the robot's own (its
            description's base.velocity_lag), filled in when the
            controller is built; a given one at least the robot's own
            (a longer lag brakes earlier). A bound, for safety; the
            compensator's base_lag is an estimate, for its prediction
            (drake_wbc.math.compensation, eq. (base_lag)).
        people: the separation from moving people, ISO/TS 15066's
            protective separation distance
            (drake_wbc.math.separation.PeopleSeparationParameters; its
            human speeds at least ISO 13855's).
        arm_follow_tolerance: rad > 0, finite: a joint's measured
            position farther than this from the arm controller's last
            position command is a fault (the arm does not follow: its
            own protective stop, an e-stop, a servo off, or held by
            hand), and an arm that far from the held command during a
            stop has the command go to where it is (or restart there
            when the stop clears first); over LCM the
            hardware interface's command guard restarts the arm's
            commands from where it is by the same tolerance
            (drake_wbc.hardware.safety.resync_arm). None: the arm's
            own, `arm_follow_tolerance_of` its joint speed limits
            (build_controller and the hardware interface fill it in).

    The arm's limits (joint positions, 1.57 rad/s, 12.56 rad/s^2) are those
    of ArmControllerParameters. Vectors are given as any sequence (a list
    in YAML) and stored as tuples, so that parameters compare with ==.
    """

    hold_time: float = DEFAULT_HOLD_TIME
    base_velocity_limits: list[float] | None = None
    base_acceleration_limits: list[float] | None = None
    stop_distance: float = DEFAULT_STOP_DISTANCE
    stop_time: float = 0.5
    base_lag: float | None = None
    people: PeopleSeparationParameters = field(
        default_factory=PeopleSeparationParameters)
    arm_follow_tolerance: float | None = None

    def __post_init__(self):
        positive("hold_time", self.hold_time)
        if self.arm_follow_tolerance is not None:
            positive("arm_follow_tolerance", self.arm_follow_tolerance)
        non_negative("stop_distance", self.stop_distance)
        positive("stop_time", self.stop_time)
        if self.base_lag is not None:
            non_negative("base_lag", self.base_lag)
        if not isinstance(self.people, PeopleSeparationParameters):
            raise ValueError(f"people = {self.people!r} is not allowed: "
                             "must be a PeopleSeparationParameters")
        for name in ("base_velocity_limits", "base_acceleration_limits"):
            if getattr(self, name) is not None:
                setattr(self, name, tuple(
                    positive_vector(name, getattr(self, name), BASE_AXES)
                    .tolist()))


def check_within_robot(params, velocity_limits, acceleration_limits,
                       velocity_lag, path="safety"):
    """Checks that the SafetyParameters `params` only tighten the robot's
    own limits: the base's velocity and acceleration limits (where given)
    at most `velocity_limits` and `acceleration_limits`, its lag (where
    given) at least `velocity_lag` (the robot's own, from its
    description).

    Raises:
        ValueError: naming the field (under `path`), its value and the
            robot's.
    """
    for name, own, unit in (
            ("base_velocity_limits", velocity_limits,
             ("m/s", "m/s", "rad/s")),
            ("base_acceleration_limits", acceleration_limits,
             ("m/s^2", "m/s^2", "rad/s^2"))):
        given = getattr(params, name)
        for i, (value, limit) in enumerate(zip(
                own if given is None else given, own, strict=True)):
            if value > limit:
                raise ValueError(
                    f"{path}.{name}[{i}] = {value!r} is not allowed: must be "
                    f"at most the robot's own {limit!r} {unit[i]} (a limit "
                    "may tighten the robot's, not widen it)")
    if params.base_lag is not None and params.base_lag < velocity_lag:
        raise ValueError(
            f"{path}.base_lag = {params.base_lag!r} is not allowed: must be "
            f"at least the robot's own {velocity_lag!r} s (a shorter lag "
            "would brake later than the base can)")


def check_vector(value, lower=-math.inf, upper=math.inf, switch=False):
    """Checks an input vector: every entry finite and in [lower, upper],
    and with `switch` exactly 0 or 1.

    The range is one for every entry (numbers) or one per entry
    (sequences of the vector's size): the wrist's wrench, whose forces
    and torques have ranges of their own (the sensor's, from the robot's
    description), and the arm's measured positions, one range a joint.

    A switch (S_hri of eqs. (cdmp-wb) and (cdmp-arm): "a pHRI mode
    switching variable with value of 0 or 1") that is neither is a fault,
    not rounded: the stages would read 0.7 as 1 and -1 as 0, and a value
    that is neither says that whatever sends it is not doing what it
    means to.

    Args:
        value: a vector (any sequence of numbers).
        lower, upper: the range allowed for every entry (numbers), or for
            each entry (sequences of the vector's size).
        switch: whether every entry must be 0 or 1.

    Returns:
        InputCheck: VALID, or the reason, index and value of the first bad
        entry (NaN, then infinite, then out of range, then not a switch,
        whichever comes first in the vector).
    """
    vector = np.asarray(value, dtype=float).ravel()
    finite = np.isfinite(vector)
    allowed = finite & (vector >= lower) & (vector <= upper)
    if switch:
        allowed &= (vector == 0.0) | (vector == 1.0)
    if np.all(allowed):
        return VALID
    i = int(np.flatnonzero(~allowed)[0])
    if np.isnan(vector[i]):
        reason = Reason.NOT_A_NUMBER
    elif not finite[i]:
        reason = Reason.INFINITE
    elif not (np.broadcast_to(lower, vector.shape)[i] <= vector[i]
              <= np.broadcast_to(upper, vector.shape)[i]):
        reason = Reason.OUT_OF_RANGE
    else:
        reason = Reason.NOT_A_SWITCH
    return InputCheck(reason, i, float(vector[i]))


def check_inputs(values, ranges):
    """Checks every input vector of the controller at once.

    Args:
        values: a sequence of input vectors (float or AutoDiffXd arrays;
            their values are checked), None for an input that is not
            connected.
        ranges: for each input, None for any finite value, or
            (lower, upper, switch): the range allowed for every entry
            (floats) or for each (tuples of floats, the input's size) and
            whether each must be 0 or 1 (`check_vector`).

    Returns:
        A tuple of one InputCheck per input (`check_vector`; VALID for
        None).
    """
    return tuple(
        VALID if value is None else check_vector(
            value_of(value), *(bounds or (-math.inf, math.inf, False)))
        for value, bounds in zip(values, ranges, strict=True))


def _input_samples(rng):
    """Random arguments of check_inputs: up to eight inputs of 1 to 6
    entries, some not connected, some with a range; valid ones (now and
    then with entries so large that their sum overflows) and ones with a
    NaN, an infinity, an entry out of its range or a switch that is
    neither 0 nor 1."""
    values, ranges = [], []
    for _ in range(rng.integers(1, 9)):
        size = int(rng.integers(1, 7))
        bounds = [None, (-math.inf, math.inf, False),
                  (0.0, math.inf, False), (0.0, 1.0, False),
                  (0.0, 1.0, True),
                  # One range an entry, some of them narrower than the
                  # values drawn.
                  (tuple(rng.choice([-math.inf, 0.0, 0.1], size).tolist()),
                   tuple(rng.choice([math.inf, 1.0, 0.9], size).tolist()),
                   False)][rng.integers(6)]
        ranges.append(bounds)
        if rng.uniform() < 0.15:
            values.append(None)
            continue
        value = rng.uniform(0.05, 0.95, size)
        if bounds is not None and bounds[2]:
            value = rng.choice([0.0, 1.0], value.size)
        if rng.uniform() < 0.05:
            value[:] = 1e308
        if rng.uniform() < 0.1:
            value[rng.integers(value.size)] = rng.choice(
                [np.nan, np.inf, -np.inf, -3.0, 3.0, 0.7, 0.5])
        values.append(value)
    return values, ranges


@kernels.fast_kernel(check_inputs, sample=_input_samples)
def check_inputs_float(values, ranges):
    """`check_inputs` of float vectors, for the control tick: one test of
    every entry present and of the ranges (a range of every entry against
    the smallest and largest entry, a range of each entry entry by entry),
    the per-input detail only when one fails."""
    # A sum of floats is finite only if every term is (a sum that
    # overflows only sends the values to the detailed checks). The
    # entries as Python floats: min and max of a few of them cost a tenth
    # of numpy's.
    entries = [None if value is None else value.tolist()
               for value in values]
    total = 0.0
    for listed in entries:
        if listed is not None:
            total += sum(listed)
    if math.isfinite(total):
        for listed, bounds in zip(entries, ranges, strict=True):
            if bounds is None or listed is None:
                continue
            lower, upper, switch = bounds
            if type(lower) is tuple:
                if not all(lo <= v <= hi for v, lo, hi in zip(
                        listed, lower, upper, strict=True)):
                    break
            elif not (lower <= min(listed) and max(listed) <= upper):
                break
            if switch and not all(v == 0.0 or v == 1.0 for v in listed):
                break
        else:
            return (VALID,) * len(values)
    return check_inputs(values, ranges)


class Following(NamedTuple):
    """That an input measures what a command drives, and must follow it.

    Attributes:
        command: the name of the command it follows (the InputGuard's
            input port of that name: the controller's last command,
            from its state).
        tolerance: the largest |input - command| of an entry that is not
            a fault, > 0 (in `unit`).
        unit: of the input and the tolerance, for the reason.
        meaning: what a larger deviation says, for the reason.
    """

    command: str
    tolerance: float
    unit: str = ""
    meaning: str = ""


def check_following(value, command, tolerance):
    """Checks that a measurement follows its command: every entry of
    `value` within `tolerance` of the same entry of `command`.

    The arm's measured joint positions against the arm controller's last
    position command: a position servo that follows lags behind a moving
    command by a small fraction of the tolerance
    (DEFAULT_ARM_FOLLOW_TOLERANCE); an arm that does not (its own
    protective stop, an e-stop, a servo off, a hand holding it) falls
    behind without bound while the controller integrates on.

    Args:
        value: the measurement (a vector of floats or AutoDiffXd; its
            values are checked).
        command: the command, of the same size.
        tolerance: the largest deviation allowed, > 0.

    Returns:
        InputCheck: VALID, or NOT_FOLLOWING with the index of the first
        entry farther than `tolerance` and its deviation value - command.
    """
    deviation = (np.asarray(value_of(value), dtype=float).ravel()
                 - np.asarray(value_of(command), dtype=float).ravel())
    beyond = np.flatnonzero(~(np.abs(deviation) <= tolerance))
    if beyond.size == 0:
        return VALID
    i = int(beyond[0])
    return InputCheck(Reason.NOT_FOLLOWING, i, float(deviation[i]))


def limit_slack(acceleration, period):
    """rad: how far beyond a joint's position limit its measured position
    may read and still be taken as on the limit: the step its acceleration
    limit allows from rest in one command period (acceleration period^2;
    an arm resting on its limit, read with an encoder's noise). A command
    held within the limits from a position farther beyond is a jump of
    the arm's setpoint: no position to start, or restart, a command from
    (drake_wbc.math.arm_control.start_within_limits, `restart_position`).

    Args:
        acceleration: (n,) or scalar, the joint acceleration limits,
            rad/s^2.
        period: the command period h, s.

    Returns:
        (n,) or scalar, rad.
    """
    return np.asarray(acceleration, dtype=float) * period * period


def beyond_limits(positions, lower, upper, acceleration, period):
    """The indices (ascending) of the joints of `positions` (n,) farther
    beyond their limits [lower, upper] than `limit_slack` of
    `acceleration` and `period`."""
    q = np.asarray(value_of(positions), dtype=float).ravel()
    slack = limit_slack(acceleration, period)
    return np.flatnonzero((q < np.asarray(lower, dtype=float) - slack)
                          | (q > np.asarray(upper, dtype=float) + slack))


class Restart(NamedTuple):
    """Where an arm's position command restarts (`restart_position`).

    Attributes:
        check: the InputCheck of the measurement against the last
            command: VALID when the command resumes from where it was
            (or for a measurement that is not finite, which is none).
        start: (n,) the positions to restart from, at rest, or None: the
            command resumes from where it was, or the measurement is no
            position to restart from (`beyond`).
        beyond: the first joint measured farther beyond its limits than
            `limit_slack` (-1: none), when the arm is elsewhere: the
            command does not restart from there.
    """

    check: InputCheck
    start: np.ndarray | None
    beyond: int = -1


def restart_position(measured, command, tolerance, lower, upper,
                     acceleration, period):
    """Where an arm's position command restarts after a stop.

    An arm farther than `tolerance` from its last command
    (`check_following`: moved by hand, or stopped on its own, during the
    stop) is held there by its servo, and a command resumed from the old
    one would ask it to jump back: the command restarts from the
    measured position, held within the joint limits (and at rest, which
    is the caller's). Within the tolerance it resumes from where it was.
    A measurement farther beyond a joint's limits than `limit_slack` is
    no position to restart from, as it is none to start from
    (drake_wbc.math.arm_control.start_within_limits): the command, held
    within the limits, would jump away from the arm. The command then
    does not restart (`Restart.beyond`): it goes on from where it was,
    within its limits. The controller's arm stage
    (drake_wbc.stages.arm_control) and the hardware interface's command
    guard (drake_wbc.hardware.safety) both restart by this rule.

    Args:
        measured: (n,) the arm's measured positions, rad (floats or
            AutoDiffXd; the result is of the same type). One that is
            not finite is no measurement.
        command: (n,) the last position command, rad.
        tolerance: rad > 0.
        lower, upper: (n,) the joint position limits, rad.
        acceleration: (n,) or scalar, the joint acceleration limits,
            rad/s^2, and period: the command period, s (`limit_slack`).

    Returns:
        Restart.
    """
    if not all_finite(measured):
        return Restart(VALID, None)
    check = check_following(measured, command, tolerance)
    if check.valid:
        return Restart(check, None)
    beyond = beyond_limits(measured, lower, upper, acceleration, period)
    if beyond.size:
        return Restart(check, None, int(beyond[0]))
    return Restart(check, np.array([
        min(max(m, low), high) for m, low, high in zip(
            np.asarray(measured).tolist(), np.asarray(lower).tolist(),
            np.asarray(upper).tolist(), strict=True)]))


def check_points(points):
    """Checks obstacle points and keeps the usable ones.

    A row with a NaN or an infinite coordinate is dropped: a scanner
    reports a beam without a return that way, and one point less of a
    scan of hundreds does not hide an obstacle (its neighbours still see
    it), whereas stopping on it would stop the robot in normal use. An
    array that is not (M, 2) numbers is malformed: a fault.

    Args:
        points: the (M, 2) array of the obstacle points' port.

    Returns:
        (kept, dropped, check): the (K, 2) float array of the finite rows
        (`points` itself when it is a float array with none to drop), the
        number of rows dropped, and VALID or a MALFORMED InputCheck (then
        kept is empty).
    """
    try:
        array = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        array = None
    if array is None or array.ndim != 2 or array.shape[1] != 2:
        return np.zeros((0, 2)), 0, InputCheck(Reason.MALFORMED)
    finite = np.isfinite(array)
    if finite.all():
        return array, 0, VALID
    rows = finite.all(axis=1)
    return array[rows], int(np.count_nonzero(~rows)), VALID


def _points_samples(rng):
    """Random arguments of check_points: scans of finite points, ones
    with rows the guard must drop (a NaN or an infinity in either
    coordinate or both, every row now and then), none, and what is not a
    float (M, 2) array of the compiled loop's type: read-only, strided,
    whole numbers, nested lists, the wrong shape, not numbers."""
    count = int(rng.choice([0, 1, 2, rng.integers(3, 400)]))
    points = rng.uniform(-5.0, 5.0, (count, 2))
    if count and rng.random() < 0.5:
        bad = rng.integers(0, count, int(rng.integers(1, count + 1)))
        points[bad, rng.integers(0, 2, len(bad))] = rng.choice(
            [np.nan, np.inf, -np.inf], len(bad))
        if rng.random() < 0.2:
            points[bad] = np.nan
    kind = rng.integers(0, 10)
    if kind == 0:
        points.flags.writeable = False
    elif kind == 1:
        points = np.asfortranarray(points)
    elif kind == 2:
        points = np.round(points).astype(int) if np.isfinite(
            points).all() else points
    elif kind == 3:
        points = points.tolist()
    elif kind == 4:
        points = [np.zeros(3), np.zeros((count, 3)), np.zeros((2, 2, 2)),
                  "points", None, [[1.0, "x"]]][rng.integers(6)]
    return (points,)


@kernels.fast_kernel(check_points, sample=_points_samples)
def check_points_float(points):
    """`check_points` of a float (M, 2) array as the LIDARs give it (C
    order, writeable): its rows counted in one compiled loop; anything
    else the reference checks."""
    if not (type(points) is np.ndarray and points.dtype == np.float64
            and points.ndim == 2 and points.shape[1] == 2
            and points.flags.c_contiguous and points.flags.writeable):
        return check_points(points)
    dropped = _non_finite_rows(points)
    if not dropped:
        return points, 0, VALID
    return points[np.isfinite(points).all(axis=1)], dropped, VALID


@compiled
def _non_finite_rows(points):
    """How many rows of (M, 2) float `points` have a coordinate that is
    NaN or infinite."""
    count = 0
    for i in range(points.shape[0]):
        if not (math.isfinite(points[i, 0]) and math.isfinite(points[i, 1])):
            count += 1
    return count


def describe(name, check, size=None, following=None):
    """A sentence that says what is wrong with the input `name`.

    Args:
        name: the input port's name.
        check: its InputCheck.
        size: the port's size, for a malformed value.
        following: the input's Following, for a deviation from its
            command (NOT_FOLLOWING).
    """
    where = f"{name}[{check.entry}]"
    if check.reason is Reason.VALID:
        return f"{name} is valid"
    if check.reason is Reason.NOT_A_NUMBER:
        return f"{where} is NaN"
    if check.reason is Reason.INFINITE:
        return f"{where} = {check.value!r} is infinite"
    if check.reason is Reason.OUT_OF_RANGE:
        return f"{where} = {check.value!r} is out of the range allowed"
    if check.reason is Reason.NOT_A_SWITCH:
        return f"{where} = {check.value!r} is not a switch: must be 0 or 1"
    if check.reason is Reason.NOT_FOLLOWING:
        unit = f" {following.unit}" if following.unit else ""
        text = (f"{where} is {abs(check.value):.3g}{unit} from the last "
                f"command (tolerance {following.tolerance:g}{unit})")
        return f"{text}: {following.meaning}" if following.meaning else text
    shape = "(M, 2)" if size is None else f"({size},)"
    return f"{name} is malformed: it must be an array of shape {shape}"


class StopState(NamedTuple):
    """The safe stop's state.

    Attributes:
        stopped: True while the controller is stopped.
        valid_time: s for which every input has been valid (0 at the tick
            at which one was not).
    """

    stopped: bool
    valid_time: float


def next_stop_state(state, invalid, time_step, hold_time):
    """The safe stop's state after one control tick.

    A tick with an invalid input stops the controller and restarts the
    valid time at 0; each valid tick adds one period, and the stop clears
    at the tick at which the valid time reaches `hold_time`, that is
    ceil(hold_time / time_step) ticks after the last invalid one.

    Args:
        state: the StopState before the tick.
        invalid: whether an input is invalid at this tick.
        time_step: the control period h > 0, s.
        hold_time: s > 0.

    Returns:
        StopState after the tick.
    """
    if invalid:
        return StopState(True, 0.0)
    valid_time = state.valid_time + time_step
    stopped = bool(state.stopped) and (
        valid_time < hold_time - TIME_TOLERANCE)
    return StopState(stopped, valid_time)


STATUS_FIELDS = ("stopped", "invalid", "reason", "input", "entry", "value",
                 "valid_time", "trips", "dropped_points")
"""The entries of the safety status vector (the controller's
`safety_status` output):

- stopped: 1.0 while the controller is in a safe stop, else 0.0.
- invalid: 1.0 while an input is invalid (stopped and not invalid: the
  inputs are valid again and the hold time runs).
- reason: the Reason code of the stop (0 when not stopped).
- input: the index of the input that caused it (among the guard's
  input_names), -1 when not stopped.
- entry: the index of its first bad entry, -1 when none.
- value: that entry's value (0.0 for NaN, so that the status stays finite;
  +-1e308 for an infinity); for NOT_FOLLOWING its deviation from the
  command, input - command.
- valid_time: s for which every input has been valid.
- trips: how many safe stops have started since the beginning.
- dropped_points: obstacle points dropped at the last tick (a row with a
  NaN or an infinite coordinate; not a fault).
"""

(_STOPPED, _INVALID, _REASON, _INPUT, _ENTRY, _VALUE, _VALID_TIME, _TRIPS,
 _DROPPED) = range(len(STATUS_FIELDS))

_INFINITY_STORED = 1e308
"""How an infinite bad value is stored in the (finite) status."""


def initial_status():
    """The status at the start: not stopped, no fault, no trips."""
    status = np.zeros(len(STATUS_FIELDS))
    status[[_INPUT, _ENTRY]] = -1.0
    return status


def stop_state_of(status):
    """The StopState that a status vector records."""
    return StopState(bool(status[_STOPPED] >= 0.5),
                     float(status[_VALID_TIME]))


def next_status(status, fault, after, dropped=0):
    """The status after one tick.

    Args:
        status: the status vector before the tick (see STATUS_FIELDS).
        fault: (input index, InputCheck) of the first invalid input at this
            tick, or None.
        after: the StopState after the tick (`next_stop_state`).
        dropped: obstacle points dropped at this tick.

    Returns:
        The new status vector: the fault's details while it lasts, kept
        while the stop holds, cleared with it; trips counts each start of a
        stop.
    """
    new = np.array(status, dtype=float)
    was_stopped = new[_STOPPED] >= 0.5
    new[_STOPPED] = 1.0 if after.stopped else 0.0
    new[_INVALID] = 0.0 if fault is None else 1.0
    new[_VALID_TIME] = after.valid_time
    new[_DROPPED] = dropped
    if fault is not None:
        index, check = fault
        value = check.value
        if not math.isfinite(value):
            value = 0.0 if math.isnan(value) else math.copysign(
                _INFINITY_STORED, value)
        new[_REASON] = int(check.reason)
        new[_INPUT] = index
        new[_ENTRY] = check.entry
        new[_VALUE] = value
    elif not after.stopped:
        new[_REASON] = new[_VALUE] = 0.0
        new[_INPUT] = new[_ENTRY] = -1.0
    if after.stopped and not was_stopped:
        new[_TRIPS] += 1.0
    return new


def status_reason(status, input_names, sizes, hold_time, followings=None):
    """What a status vector says, as a sentence ("" when not stopped).

    Args:
        status: the status vector.
        input_names: the inputs' names, in the order of its `input`.
        sizes: their sizes (None for the obstacle points).
        hold_time: s, for the message while the stop holds.
        followings: the inputs' Following (None for one that follows no
            command), in the same order; None for none.
    """
    if status[_STOPPED] < 0.5:
        return ""
    i = int(status[_INPUT])
    reason = Reason(int(status[_REASON]))
    value = float(status[_VALUE])
    if reason is Reason.INFINITE:
        value = math.copysign(math.inf, value)
    text = describe(input_names[i],
                    InputCheck(reason, int(status[_ENTRY]), value),
                    sizes[i], followings[i] if followings else None)
    if status[_INVALID] < 0.5:
        text += (f"; resuming from where it is after {hold_time:g} s"
                 if reason is Reason.NOT_FOLLOWING else
                 f"; the inputs are valid again, resuming after "
                 f"{hold_time:g} s of valid inputs")
    return text
