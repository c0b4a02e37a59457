"""Teach and repeat: a whole-body movement learned as a DMP (Sec. III-C).

The paper leaves the forcing term f(s) of eq. (6) at zero; here it is
learned from demonstrations given by hand in pHRI mode (S_hri = 1,
eq. (cdmp-wb)) and played back by the whole-body CDMP
(drake_wbc.stages.WholeBodyCdmp with cdmp.MovementReplay).

What is learned: the TCP's position x, y, z and yaw in the world, the
entries 0, 1, 2 and 5 of the whole-body DMP's twist state [v; w]
(displacements from its start, in the world); roll and pitch keep f = 0
and g = 0. The forcing is in absolute units (drake_wbc.math.dmp), so the
learned shape superposes unchanged on a moved goal.

Recording and its start and stop markers: drake_wbc.math.demonstration.

Learning (`learn_movement`): each demonstration is normalised to a
common duration (their mean), its forcing targets
(dmp.forcing_targets, goal its last sample) and design matrix
(dmp.design_matrix) are stacked with the others', and the
weights are one ridge fit (dmp.fit_weights).
Several demonstrations thus average. `LearnedMovement.save`/`load` write
and read it as a small YAML file.
"""

from bisect import bisect_right
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import yaml

from drake_wbc.math import dmp
from drake_wbc.math.demonstration import DIMENSIONS, Demonstration
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.loading import screened_data, short_value, shortened
from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    positive,
    within_site,
)

LEARNED_TWIST_INDICES = (0, 1, 2, 5)
"""The entries of the whole-body DMP's [v; w] state that are learned:
x, y, z and yaw."""

DEFAULT_NUM_BASIS = 40
"""Basis functions of a learned movement unless given (a few per second
of a movement of several seconds)."""

PLOT_PERIOD = 0.05
"""s: the sample period of the demonstrations kept in a movement file."""

MAX_KEPT_SAMPLES = 4000
"""The most samples of all the demonstrations kept in a movement file,
together (10 values each: 40,000 of the 50,000 that the loader reads,
drake_wbc.math.loading.MAX_NODES, beside at most 5,000 weights): a
demonstration longer than 200 s is kept at a longer period than
PLOT_PERIOD."""

ROLLOUT_RESOLUTION = 0.25
"""The largest step of a MovementPlayer's rollouts times the played DMP's
fastest rate (dmp.fastest_rate): 0.125 at the default gains and tau = 1
with the 5 ms step; Runge-Kutta's fourth order diverges from about 2.8,
which a movement played 50 times faster than it was taught passed with
the fixed 5 ms step (its reference grew to 1e49 m)."""

MAX_ROLLOUT_STEPS = 100_000
"""The most steps of each of a MovementPlayer's two rollouts (about 8 s
each to build, at 12,000 steps/s): a movement of up to 495 s as played,
or the shipped 6 s one played down to tau = tau_0 / 198 (at tau_0 /
200 its 5.03 s of rollout take 100,600 steps of 50 us)."""


@dataclass(frozen=True, eq=False)
class LearnedMovement:
    """A movement learned from demonstrations.

    Attributes:
        params: the DmpParameters it was learned with (duration the
            demonstrations' common duration).
        weights: (num_basis, 4) forcing weights (x, y, z, yaw), in
            absolute units.
        start, goal: (4,) the TCP's mean start and goal [x, y, z, yaw] in
            the world (x, y and z within the scene's site, +-SITE_EXTENT
            of drake_wbc.math.validation).
        demonstrations: the demonstrations (possibly resampled), for plots.
        source: how it was made (e.g. the command), for the file's header.
    """

    params: dmp.DmpParameters
    weights: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    demonstrations: tuple = ()
    source: str = ""

    def __post_init__(self):
        if not isinstance(self.params, dmp.DmpParameters):
            raise ValueError(f"params = {self.params!r} is not allowed: "
                             "must be a DmpParameters")
        object.__setattr__(self, "weights", as_matrix(
            "weights", self.weights, (self.params.num_basis, 4)))
        for name in ("start", "goal"):
            pose = as_vector(name, getattr(self, name), 4)
            # Points of the scene, as a replay's goal and start.
            object.__setattr__(self, name, within_site(
                name, pose, lengths=pose[:3]))
        object.__setattr__(self, "demonstrations",
                           tuple(self.demonstrations))

    def rollout(self, goal=None, tau=None, dt=0.01, extra_time=1.0):
        """The learned DMP integrated by dmp.rollout from the start to
        `goal` (4,) (the learned one if None) with temporal scaling `tau`
        (the learned one if None): (t, y, yd), y in the world."""
        goal = self.goal if goal is None else as_vector("goal", goal, 4)
        params = self.params if tau is None else self.params.with_tau(tau)
        return dmp.rollout(params, self.start, goal,
                           params.duration + extra_time, dt, self.weights)

    def save(self, path):
        """Writes the movement as YAML (numbers rounded: positions to
        0.1 um, weights to 6 significant digits), with a header."""
        p = self.params
        document = {
            "dimensions": list(DIMENSIONS),
            "dmp": {"alpha_z": float(p.alpha_z),
                    "beta_z": float(p.resolved_beta_z),
                    "alpha_s": float(p.resolved_alpha_s),
                    "tau": float(p.tau), "duration": _round(p.duration),
                    "num_basis": int(p.num_basis)},
            "start": _round(self.start),
            "goal": _round(self.goal),
            "weights": [[float(f"{w:.6g}") for w in row]
                        for row in self.weights],
            "demonstrations": [_demo_document(
                d, max(MAX_KEPT_SAMPLES // len(self.demonstrations), 3))
                for d in self.demonstrations],
        }
        header = (
            "# A whole-body movement learned as a DMP "
            "(drake_wbc.math.movement):"
            "\n# the forcing weights of the TCP's x, y, z and yaw in the "
            "world (eq. (6), absolute\n# units), its start and goal, and "
            "the demonstrations, resampled, for plots.\n")
        if self.source:
            header += f"# Made by: {self.source}\n"
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(header + yaml.safe_dump(
            document, default_flow_style=None, sort_keys=False, width=100))
        return path

    @classmethod
    def load(cls, path):
        """Reads a movement written by `save`, as the scenarios' loader
        reads a file (drake_wbc.math.loading.screened_data: at most
        MAX_BYTES, no alias bomb, no deep nesting).

        Raises:
            ValueError: naming the file, the field and what is wrong in
                it.
        """
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"file = {str(path)!r} is not allowed: no "
                             "such movement file")
        try:
            document = screened_data(path)
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None
        except yaml.YAMLError as error:
            raise ValueError(f"{path}: not valid YAML: {error}") from None
        try:
            return cls._from_document(document)
        except (TypeError, ValueError) as error:
            raise ValueError(f"{path}: not a learned movement: "
                             f"{shortened(str(error))}") from None

    @classmethod
    def _from_document(cls, document):
        """The LearnedMovement of a document (plain data) of `save`."""
        keys = "dimensions, dmp, start, goal, weights and demonstrations"
        if not isinstance(document, dict):
            raise ValueError(f"the document = {short_value(document)} is not "
                             f"allowed: must be a mapping of {keys}")
        for key in ("dmp", "start", "goal", "weights"):
            if key not in document:
                raise ValueError(f"{key} is missing: a learned movement "
                                 f"has {keys}")
        dimensions = document.get("dimensions", list(DIMENSIONS))
        if dimensions != list(DIMENSIONS):
            raise ValueError(f"dimensions = {short_value(dimensions)} is not "
                             f"allowed: must be {list(DIMENSIONS)}")
        if not isinstance(document["dmp"], dict):
            raise ValueError(f"dmp = {short_value(document['dmp'])} is not "
                             "allowed: must be a mapping of DmpParameters' "
                             "fields")
        params = dmp.DmpParameters(**document["dmp"])
        demos = []
        for i, demo in enumerate(document.get("demonstrations") or []):
            if not isinstance(demo, dict) or not {"time", "tcp"} <= set(demo):
                raise ValueError(
                    f"demonstrations[{i}] = {short_value(demo)} is not "
                    "allowed: must be a mapping of time, tcp and (optional) "
                    "base")
            try:
                demos.append(Demonstration(demo["time"], demo["tcp"],
                                           demo.get("base")))
            except ValueError as error:
                raise ValueError(f"demonstrations[{i}].{error}") from None
        return cls(params, document["weights"], document["start"],
                   document["goal"], tuple(demos))


def _round(value, decimals=7):
    if np.ndim(value) == 0:
        return round(float(value), decimals)
    return [_round(v, decimals) for v in value]


def _demo_document(demo, most):
    """`demo` as plain data, every PLOT_PERIOD (or fewer: at most `most`
    samples, its last one kept)."""
    step = max(int(round(PLOT_PERIOD / np.median(np.diff(demo.time)))), 1,
               -(-(demo.time.size - 1) // (most - 1)))
    keep = np.unique(np.append(np.arange(0, demo.time.size, step),
                               demo.time.size - 1))
    document = {"time": _round(demo.time[keep], 4),
                "tcp": _round(demo.tcp[keep], 5)}
    if demo.base is not None:
        document["base"] = _round(demo.base[keep], 5)
    return document


def learn_movement(demonstrations, params=None, num_basis=None,
                   regularisation=1e-6, source=""):
    """Learns a LearnedMovement from one or several Demonstrations.

    Args:
        demonstrations: a Demonstration or a sequence of them; each should
            start and end at rest.
        params: DmpParameters (gains, tau, num_basis); its duration is
            replaced by the demonstrations' mean duration (alpha_s by the
            default of that duration when None). None: the defaults with
            DEFAULT_NUM_BASIS.
        num_basis: overrides params.num_basis when given.
        regularisation: the relative ridge factor of dmp.fit_weights.
        source: how it was made, kept in the file's header.

    Returns:
        LearnedMovement, its start and goal the demonstrations' means
        (each demonstration's yaw turned by whole turns to start within pi
        of the first's).
    """
    if isinstance(demonstrations, Demonstration):
        demonstrations = [demonstrations]
    demonstrations = list(demonstrations)
    if not demonstrations or not all(
            isinstance(d, Demonstration) for d in demonstrations):
        raise ValueError(f"demonstrations = {demonstrations!r} is not "
                         "allowed: must be one or more Demonstration")
    # Each yaw is unwrapped from its own first sample: turned by whole
    # turns to start within pi of the first demonstration's, so that the
    # means of the starts and goals are of the same heading.
    first = demonstrations[0].tcp[0, 3]
    demonstrations = [
        replace(d, tcp=d.tcp - [0.0, 0.0, 0.0, 2.0 * np.pi * np.round(
            (d.tcp[0, 3] - first) / (2.0 * np.pi))])
        for d in demonstrations]
    duration = float(np.mean([d.duration for d in demonstrations]))
    params = params or dmp.DmpParameters(num_basis=DEFAULT_NUM_BASIS)
    params = replace(params, duration=positive("duration", duration),
                     num_basis=(params.num_basis if num_basis is None
                                else num_basis))
    designs, targets = [], []
    for demo in demonstrations:
        t = (demo.time - demo.time[0]) * (duration / demo.duration)
        yd, ydd = dmp.demonstration_derivatives(t, demo.tcp)
        targets.append(dmp.forcing_targets(
            t, demo.tcp, yd, ydd, demo.tcp[-1], params))
        designs.append(dmp.design_matrix(
            dmp.canonical_phase(t, params), params))
    weights = dmp.fit_weights(np.vstack(designs), np.vstack(targets),
                              regularisation)
    return LearnedMovement(
        params, weights, np.mean([d.tcp[0] for d in demonstrations], axis=0),
        np.mean([d.tcp[-1] for d in demonstrations], axis=0),
        tuple(demonstrations), source)


def interpolated_row(x, times, rows, left=None, right=None):
    """The row of a table at x, linear between its times: np.interp(x,
    times, column, left, right) of every column of `rows`.

    Args:
        x: a float.
        times: a strictly increasing list of N floats.
        rows: a list of N lists of floats (one a time, all as long).
        left, right: the value of every column before times[0] and after
            times[-1]; None to hold the first or last row.

    Returns:
        a new list, one float a column.
    """
    columns = np.asarray(rows, dtype=float).T
    return [float(np.interp(x, times, column, left, right))
            for column in columns]


def _table_inputs(rng):
    """A random table and a time before, after, on, just beside and
    between its times, for interpolated_row_float: with and without
    values outside, flat stretches, one time in twenty NaN."""
    n = int(rng.integers(1, 40))
    times = np.cumsum(rng.uniform(1e-3, 1.0, n)) - rng.uniform(0.0, 5.0)
    rows = rng.normal(size=(n, int(rng.integers(1, 5))))
    if n > 1 and rng.uniform() < 0.3:
        rows[1] = rows[0]
    x = rng.choice([times[0] - rng.random(), times[-1] + rng.random(),
                    times[rng.integers(n)], np.nextafter(times[0], -np.inf),
                    np.nextafter(times[-1], np.inf),
                    rng.uniform(times[0], times[-1])])
    if rng.uniform() < 0.05:
        x = np.nan
    left, right = ((None, None) if rng.uniform() < 0.5
                   else tuple(rng.choice([0.0, -3.0, 4.0], 2).tolist()))
    return float(x), times.tolist(), rows.tolist(), left, right


@fast_kernel(interpolated_row, sample=_table_inputs)
def interpolated_row_float(x, times, rows, left=None, right=None):
    """`interpolated_row` in plain floats: numpy's operations in numpy's
    order (its search, its slope and its fallbacks), so the same numbers
    without a numpy call a column: the replay's tables and the scene's
    schedules, each control tick."""
    if x != x:  # NaN: numpy's own answer
        return interpolated_row(x, times, rows, left, right)
    j = bisect_right(times, x) - 1
    if j < 0:
        return list(rows[0]) if left is None else [left] * len(rows[0])
    if j >= len(times) - 1 or times[j] == x:
        if right is not None and x > times[-1]:
            return [right] * len(rows[-1])
        return list(rows[j])
    t0, t1 = times[j], times[j + 1]
    values = []
    for a, b in zip(rows[j], rows[j + 1], strict=True):
        slope = (b - a) / (t1 - t0)
        value = slope * (x - t0) + a
        if value != value:  # numpy's fallbacks, for infinite values
            value = slope * (x - t1) + b
            if value != value and a == b:
                value = a
        values.append(value)
    return values


def resolve_movement_file(file):
    """The path of a movement file: as given if absolute or found from
    the working folder, else in the repository's diagrams/.

    Raises:
        ValueError: naming the file and the places looked in.
    """
    if not str(file).strip():
        raise ValueError(f"file = {str(file)!r} is not allowed: must name "
                         "the learned movement's file")
    path = Path(file)
    if path.is_file():
        return path
    here = Path(__file__).resolve().parents[1]  # the package
    tried = [str(path.resolve())]
    if not path.is_absolute():
        for folder in (here / "diagrams", here.parent / "diagrams"):
            if (folder / path).is_file():
                return folder / path
            tried.append(str(folder / path))
    raise ValueError(f"file = {str(file)!r} is not allowed: no movement "
                     f"file there (looked for {', '.join(tried)})")


ROLLOUT_TAIL = 5.0
"""s: a MovementPlayer's rollouts run this long past the played
movement's duration (the DMP settling on its goal)."""


def rollout_step(movement, tau, dt=0.005, source=None, name="tau"):
    """The step of a MovementPlayer's rollouts of `movement` played at
    `tau`: `dt`, or shorter where the played DMP is faster
    (ROLLOUT_RESOLUTION / dmp.fastest_rate).

    Args:
        movement: a LearnedMovement.
        tau: the tau it is played at (> 0).
        dt: the longest step, s.
        source: the movement's file, for the messages.
        name: what the caller calls tau (a command's --tau).

    Raises:
        ValueError: naming the movement's duration or `name` when the
            rollouts would need more than MAX_ROLLOUT_STEPS steps.
    """
    longest = positive("dt", dt)
    played = movement.params.with_tau(positive(name, tau))
    length = played.duration + ROLLOUT_TAIL
    step = min(longest, ROLLOUT_RESOLUTION / dmp.fastest_rate(played))
    refused = (f"{name} = {tau!r} is not allowed for the movement"
               f"{'' if source is None else ' ' + str(source)} (learned at "
               f"tau = {movement.params.tau:g} over "
               f"{movement.params.duration:.6g} s): played ")
    if length / longest > MAX_ROLLOUT_STEPS:
        longest_played = MAX_ROLLOUT_STEPS * longest - ROLLOUT_TAIL
        if tau != movement.params.tau:  # the tau it is played at counts
            pace = (f"{tau / movement.params.tau:.3g} times slower"
                    if tau > movement.params.tau else
                    f"{movement.params.tau / tau:.3g} times faster")
            raise ValueError(
                f"{refused}{pace}, it would last {played.duration:.6g} s, "
                f"at most {longest_played:g} s (its rollouts take at most "
                f"{MAX_ROLLOUT_STEPS} steps of {longest:g} s); play it "
                "faster (a smaller tau)")
        raise ValueError(
            f"{source or 'the movement'}: dmp.duration = "
            f"{movement.params.duration:.6g} s is not allowed: a movement "
            f"lasts at most {longest_played:g} s (its rollouts take at "
            f"most {MAX_ROLLOUT_STEPS} steps of {longest:g} s)")
    if length / step > MAX_ROLLOUT_STEPS:
        raise ValueError(
            f"{refused}{movement.params.tau / tau:.3g} times faster, its "
            f"rollouts would take {length / step:.3g} steps of {step:.3g} "
            f"s, at most {MAX_ROLLOUT_STEPS}; play it slower (a larger tau)")
    return step


class MovementPlayer:
    """The goal and forcing term that a learned movement adds to the
    whole-body DMP over time, and the pose it plays (pure numpy;
    WholeBodyCdmp and MovementTracking run it).

    From replay.start_time on: f(s) with s the closed-form canonical
    phase of t - start_time (eq. (7)), and the goal g (displacement from
    where the DMP started, in the twist entries LEARNED_TWIST_INDICES);
    before it both are zero. A moved goal is reached along the
    demonstration's own progress: g(t) = g_0 + p(t) (g - g_0), g_0 the
    learned goal and p(t) from 0 to 1 the fraction of the learned
    rollout's path covered at t (its yaw's, turned either way, for a turn
    on the spot; 1 throughout for a rollout that moves less than 1e-6 m
    and rad) (a moving goal, which the absolute-units
    forcing allows, drake_wbc.math.dmp): the moved part of the motion then has
    the demonstration's velocity profile, and the start does not jump.
    The transformation system runs with the movement's alpha_z, beta_z
    and tau (`transformation_parameters`).

    Args:
        movement: a LearnedMovement.
        replay: a cdmp.MovementReplay (goal, tau, start_time, start).
        dt: the longest step of the precomputed rollouts (progress,
            reference), s; shorter where the played DMP is faster
            (ROLLOUT_RESOLUTION).

    Raises:
        ValueError: naming the movement's duration or tau when the
            rollouts would need more than MAX_ROLLOUT_STEPS steps.
    """

    def __init__(self, movement, replay, dt=0.005):
        self.movement, self.replay = movement, replay
        tau = movement.params.tau if replay.tau is None else replay.tau
        self.params = movement.params.with_tau(tau)
        length = self.params.duration + ROLLOUT_TAIL
        dt = rollout_step(movement, tau, dt, source=replay.file)
        self.start = movement.start if replay.start is None else np.asarray(
            replay.start, dtype=float)
        goal = movement.goal if replay.goal is None else np.asarray(
            replay.goal, dtype=float)
        learned = movement.goal - movement.start
        delta = goal - self.start
        # The yaw's change taken within pi of the learned one (a goal's
        # yaw may be given in any turn).
        delta[3] = learned[3] + (delta[3] - learned[3] + np.pi) % (
            2.0 * np.pi) - np.pi
        self.goal, self.learned_goal = np.zeros(6), np.zeros(6)
        self.goal[list(LEARNED_TWIST_INDICES)] = delta
        self.learned_goal[list(LEARNED_TWIST_INDICES)] = learned
        self.start_time = float(replay.start_time)
        self.tracking_gain = float(replay.tracking_gain)
        self._cache = {}
        t, y, _ = dmp.rollout(self.params, np.zeros(4), learned, length, dt,
                              movement.weights)
        path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(
            np.diff(y[:, :3], axis=0), axis=1))])
        if path[-1] < 1e-6:  # a turn on the spot: the yaw's progress
            path = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(
                y[:, 3])))])
        self._times = t
        # Less than 1e-6 m and rad is a movement at rest (the fit's
        # rounding): its goal moves at once.
        self._progress = (path / path[-1] if path[-1] >= 1e-6
                          else 0.0 * t + 1)
        # The per-tick path (`drive_terms`, `reference`) runs the float
        # kernels of eqs. (6), (7) and of the tables (plain floats and few
        # numpy calls): the tables as lists, the weights (in the learned
        # twist entries, zero elsewhere) as an array.
        self._time_list = t.tolist()
        self._progress_rows = [[p] for p in np.broadcast_to(
            self._progress, t.shape).tolist()]
        self._goal_change = (self.goal - self.learned_goal).tolist()
        self._learned_goal_list = self.learned_goal.tolist()
        self._weights = np.zeros((self.params.num_basis, 6))
        self._weights[:, list(LEARNED_TWIST_INDICES)] = movement.weights
        _, self._reference, _ = dmp.rollout(
            self.params, np.zeros(4), None, length, dt, movement.weights,
            lambda t: self.goal_at(t)[list(LEARNED_TWIST_INDICES)])
        self._reference_rows = self._reference.tolist()
        self._start_list = np.asarray(self.start, dtype=float).tolist()

    def active(self, t):
        """True from start_time on."""
        return t >= self.start_time - 1e-9

    def goal_at(self, elapsed):
        """g (6,) at `elapsed` s after start_time (module docstring)."""
        return np.array(self._goal_list(float(elapsed)))

    def _goal_list(self, elapsed):
        """`goal_at` of a float, as a list."""
        p = interpolated_row_float(elapsed, self._time_list,
                                   self._progress_rows)[0]
        return [g + p * change for g, change in
                zip(self._learned_goal_list, self._goal_change,
                    strict=True)]

    def reference(self, t):
        """p*(t): the TCP's pose [x, y, z, yaw] in the world that the DMP
        plays at time t (its own rollout, from rest at the start; the
        start before start_time)."""
        elapsed = max(float(t) - self.start_time, 0.0)
        return np.array([s + r for s, r in zip(
            self._start_list, interpolated_row_float(
                elapsed, self._time_list, self._reference_rows),
            strict=True)])

    def goal_and_forcing(self, t):
        """(g, f), each (6,), at time t (float)."""
        terms = self.drive_terms(t)
        return np.array(terms[:6]), np.array(terms[6:])

    def drive_terms(self, t):
        """g and f at time t (float) as one list of 12 floats, [g; f], not
        to be changed; the last few times' values are remembered (a
        control tick asks for the same ones)."""
        cached = self._cache.get(t)
        if cached is None:
            cached = self._drive_terms(t)
            if len(self._cache) >= 8:
                del self._cache[next(iter(self._cache))]
            self._cache[t] = cached
        return cached

    def _drive_terms(self, t):
        """[g; f] at time t: f(s) of eq. (6) (the float kernel of
        dmp.forcing_term) at the closed-form phase s of eq. (7) (that of
        dmp.canonical_phase)."""
        if not self.active(t):
            return [0.0] * 12
        elapsed = max(t - self.start_time, 0.0)
        s = dmp.canonical_phase_float(elapsed, self.params)
        forcing = dmp.forcing_term_float(s, self._weights, self.params)
        return self._goal_list(elapsed) + forcing.tolist()

    def transformation_parameters(self, dmp_params):
        """`dmp_params` with the movement's alpha_z, beta_z and tau."""
        return replace(dmp_params, alpha_z=self.params.alpha_z,
                       beta_z=self.params.resolved_beta_z,
                       tau=self.params.tau)
