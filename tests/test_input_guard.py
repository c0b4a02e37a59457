"""InputGuard against an independent tick-by-tick model of what it must
do, in double and in AutoDiffXd (the float kernel of its checks and the
reference), on seeded random inputs with NaN, infinite, out-of-range and
huge entries, malformed and partly invalid obstacle points, and optional
inputs left unconnected; check_points and next_status against their
definitions."""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import (
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)
from pydrake.common.value import Value
from pydrake.systems.framework import (
    InputPortIndex,
    OutputPortIndex,
    PortDataType,
)
from pydrake.systems.primitives import Linearize

from drake_wbc.math import safety
from drake_wbc.math.safety import (
    STATUS_FIELDS,
    Following,
    Reason,
    SafetyParameters,
)
from drake_wbc.stages.safety import GuardedInput, InputGuard

H = 0.01
HOLD = 0.05  # five ticks, so that the random runs clear their stops often
F = {name: i for i, name in enumerate(STATUS_FIELDS)}
TICKS = 240

SPECS = (
    GuardedInput("state", 6),
    GuardedInput("position", 3, initial=(0.1, 0.2, 0.3)),
    GuardedInput("reference", 4, zero_when_stopped=True),
    GuardedInput("wrench", 6, (("wrench", [0.5] * 6),)),
    GuardedInput("switch", 1, (("switch.a", [1.0]), ("switch.b", [0.0]))),
    GuardedInput("gain", 1, (("gain", [2.0]),), lower=0.0, upper=math.inf),
    GuardedInput("ratio", 2, (("ratio", [0.5, 0.5]),), lower=0.0,
                 upper=1.0),
    GuardedInput("held", 2, (("held", [0.0, 0.0]),),
                 zero_when_stopped=True),
)
POINTS = "points"


def make_guard():
    return InputGuard(SPECS, points_name=POINTS, time_step=H,
                      params=SafetyParameters(hold_time=HOLD))


# --- the inputs of a random run ---------------------------------------


def random_vector(rng, spec, fault):
    """A valid vector for `spec`, or with one bad entry if `fault`."""
    value = rng.uniform(0.05, 0.95, spec.size)
    if rng.random() < 0.05:
        value[:] = 1e308  # finite, but its sum overflows
    if fault:
        entry = rng.integers(spec.size)
        value[entry] = rng.choice([np.nan, np.inf, -np.inf, -3.0, 3.0])
    return value


def random_points(rng, fault):
    kind = rng.random()
    if fault:
        return [np.zeros(3), np.zeros((2, 3)), "not points",
                [[1.0, 2.0, 3.0]]][rng.integers(4)]
    if kind < 0.5:
        return rng.normal(size=(rng.integers(0, 6), 2))
    if kind < 0.7:
        points = rng.normal(size=(6, 2))
        for _ in range(rng.integers(1, 4)):
            points[rng.integers(6), rng.integers(2)] = rng.choice(
                [np.nan, np.inf, -np.inf])
        return points
    if kind < 0.8:
        return np.full((3, 2), 1e308)
    if kind < 0.9:
        return np.arange(8).reshape(4, 2)  # integers
    return [[0.5, 1.0], [2.0, -1.0]]


def random_run(seed):
    """Per tick, {port name: value or None (left as it was)}: each port is
    connected from a tick of its own on (the optional ones may stay
    unconnected), and about one tick in ten has an invalid input."""
    rng = np.random.default_rng(seed)
    names = [spec.name for spec in SPECS] + [POINTS]
    first = {name: 0 for name in names[:3]}
    for name in names[3:]:
        first[name] = int(rng.choice([0, 30, TICKS]))
    ticks = []
    for k in range(TICKS):
        faulty = rng.integers(len(names)) if rng.random() < 0.1 else None
        values = {}
        for i, name in enumerate(names):
            if k < first[name]:
                continue
            fault = i == faulty
            if name == POINTS:
                values[name] = random_points(rng, fault)
            else:
                values[name] = random_vector(rng, SPECS[i], fault)
        ticks.append(values)
    return ticks


# --- running a guard ----------------------------------------------------


def run(guard, ticks, autodiff=False):
    """Per tick: {output name: value} and the state after the update."""
    system = guard.ToAutoDiffXd() if autodiff else guard
    context = system.CreateDefaultContext()
    records = []
    for k, values in enumerate(ticks):
        context.SetTime(k * H)
        for name, value in values.items():
            port = system.GetInputPort(name)
            if port.get_data_type() == PortDataType.kAbstractValued:
                port.FixValue(context, Value[object](value))
            elif autodiff:
                port.FixValue(context, InitializeAutoDiff(
                    value, np.ones((value.size, 1))).ravel())
            else:
                port.FixValue(context, value)
        outputs = {}
        for i in range(system.num_output_ports()):
            port = system.get_output_port(i)
            value = port.Eval(context)
            if port.get_data_type() == PortDataType.kVectorValued:
                value = np.asarray(value)
                if autodiff:
                    value = (ExtractValue(value).ravel(),
                             ExtractGradient(value))
                else:
                    value = value.copy()
            outputs[port.get_name()] = value
        update = system.EvalUniquePeriodicDiscreteUpdate(context)
        state = update.get_vector(0).CopyToVector()
        records.append((outputs, ExtractValue(state).ravel()
                        if autodiff else state))
        context.SetDiscreteState(state)
    return records


@pytest.fixture(scope="module")
def runs():
    """(inputs, double run, AutoDiffXd run) for three seeds."""
    guard = make_guard()
    return [(ticks, run(guard, ticks), run(guard, ticks, autodiff=True))
            for ticks in map(random_run, range(3))]


# --- an independent model of the guard --------------------------------


def first_bad_entry(value, lower, upper):
    """(Reason, entry, value) of the first bad entry, or None."""
    for j, x in enumerate(value):
        if math.isnan(x):
            return Reason.NOT_A_NUMBER, j, x
        if math.isinf(x):
            return Reason.INFINITE, j, x
        if not lower <= x <= upper:
            return Reason.OUT_OF_RANGE, j, x
    return None


def model(ticks):
    """What each tick must give, entry by entry, in plain Python."""
    last = {spec.name: np.zeros(spec.size) if spec.initial is None
            else np.array(spec.initial, dtype=float) for spec in SPECS}
    current = {}
    stopped, valid_time, trips = False, 0.0, 0
    status = [0.0, 0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 0.0]
    expected = []
    for values in ticks:
        current.update(values)
        fault = None
        for i, spec in enumerate(SPECS):
            if spec.name in current:
                bad = first_bad_entry(current[spec.name], spec.lower,
                                      spec.upper)
                if bad and fault is None:
                    fault = (i, *bad)
        points, dropped = np.zeros((0, 2)), 0
        if POINTS in current:
            raw = current[POINTS]
            array = np.asarray(raw if not isinstance(raw, str) else [[[]]])
            if array.ndim == 2 and array.shape[1] == 2:
                keep = [row for row in array.astype(float)
                        if all(math.isfinite(x) for x in row)]
                points = np.array(keep).reshape(-1, 2)
                dropped = len(array) - len(keep)
            elif fault is None:
                fault = (len(SPECS), Reason.MALFORMED, -1, math.nan)
        # The stop: on at a fault, off after HOLD of valid ticks.
        if fault is not None:
            stop, valid_time = True, 0.0
        else:
            valid_time += H
            stop = stopped and valid_time < HOLD - 1e-9
        outputs = {}
        for spec in SPECS:
            value = current.get(spec.name)
            good = value is not None and first_bad_entry(
                value, spec.lower, spec.upper) is None
            for name, default in spec.outputs or ((spec.name, None),):
                if spec.zero_when_stopped and stop:
                    outputs[name] = np.zeros(spec.size)
                elif value is None:
                    outputs[name] = np.array(default, dtype=float)
                else:
                    outputs[name] = value if good else last[spec.name]
            if good:
                last[spec.name] = value
        outputs["stop"] = np.array([float(stop)])
        outputs["stopped"] = np.array([status[0]])
        outputs["safety_status"] = np.array(status)
        outputs[POINTS] = points
        trips += stop and not stopped
        if fault is not None:
            index, reason, entry, value = fault
            if math.isnan(value):
                value = 0.0
            elif math.isinf(value):
                value = math.copysign(1e308, value)
            detail = [float(reason), index, entry, value]
        elif not stop:
            detail = [0.0, -1.0, -1.0, 0.0]
        else:
            detail = status[2:6]
        status = [float(stop), float(fault is not None), *detail,
                  valid_time, float(trips), float(dropped)]
        stopped = stop
        state = np.concatenate([last[spec.name] for spec in SPECS]
                               + [status])
        expected.append((outputs, state))
    return expected


# --- the tests -----------------------------------------------------------


def test_the_runs_cover_the_cases(runs):
    statuses = np.array([state[-len(STATUS_FIELDS):] for _, double, _ in runs
                         for _, state in double])
    reasons = set(statuses[:, F["reason"]].astype(int))
    assert reasons == {0, 1, 2, 3, 4}
    assert set(statuses[:, F["input"]].astype(int)) == set(range(-1, 9))
    assert statuses[:, F["stopped"]].any()
    assert not statuses[:, F["stopped"]].all()
    assert statuses[:, F["trips"]].max() >= 5
    assert statuses[:, F["dropped_points"]].any()


@pytest.mark.parametrize("seed", range(3))
def test_double_matches_the_model(runs, seed):
    ticks, double, _ = runs[seed]
    for k, ((outputs, state), (want, want_state)) in enumerate(
            zip(double, model(ticks), strict=True)):
        for name, value in want.items():
            np.testing.assert_array_equal(
                outputs[name], value, err_msg=f"tick {k}: {name}")
        np.testing.assert_array_equal(state, want_state,
                                      err_msg=f"tick {k}: state")


@pytest.mark.parametrize("seed", range(3))
def test_double_matches_autodiff(runs, seed):
    _, double, autodiff = runs[seed]
    for k, ((outputs, state), (ad_outputs, ad_state)) in enumerate(
            zip(double, autodiff, strict=True)):
        np.testing.assert_array_equal(state, ad_state, err_msg=f"tick {k}")
        for name, value in outputs.items():
            other = ad_outputs[name]
            if isinstance(other, tuple):
                np.testing.assert_array_equal(value, other[0],
                                              err_msg=f"tick {k}: {name}")
            elif isinstance(value, np.ndarray):
                np.testing.assert_array_equal(value, other)
            else:
                assert value == other, (k, name)


def test_autodiff_passes_derivatives_of_inputs_only(runs):
    """A guarded input carries its derivatives through (each input's are
    ones here); the status and the stop flags carry none."""
    for ticks, _, autodiff in runs:
        check_derivatives(ticks, autodiff)


def check_derivatives(ticks, autodiff):
    for values, (ad_outputs, _) in zip(ticks, autodiff, strict=True):
        for name in ("stop", "stopped", "safety_status"):
            assert not ad_outputs[name][1].any(), name
        if np.isfinite(values["state"]).all():
            np.testing.assert_array_equal(ad_outputs["state"][1],
                                          np.ones((6, 1)))


def test_reason_sentence(runs):
    for _, double, _ in runs:
        for outputs, _ in double:
            stopped = outputs["safety_status"][F["stopped"]]
            assert (outputs["safety_reason"] == "") == (stopped < 0.5)


def test_the_last_valid_sample_initially():
    """The first ticks' `position` is `initial` until a valid sample."""
    guard = make_guard()
    context = guard.CreateDefaultContext()
    bad = np.array([0.1, np.nan, 0.3])
    guard.GetInputPort("state").FixValue(context, np.zeros(6))
    guard.GetInputPort("position").FixValue(context, bad)
    guard.GetInputPort("reference").FixValue(context, np.ones(4))
    np.testing.assert_array_equal(
        guard.GetOutputPort("position").Eval(context), [0.1, 0.2, 0.3])
    guard.set_last_valid(context, "position", [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(
        guard.GetOutputPort("position").Eval(context), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(
        guard.GetOutputPort("reference").Eval(context), np.zeros(4))


def test_check_points_keeps_the_finite_rows():
    rng = np.random.default_rng(4)
    cases = [np.zeros((0, 2)), rng.normal(size=(50, 2)),
             np.full((2, 2), 1e308), np.asfortranarray(rng.normal(
                 size=(7, 2))), rng.normal(size=(10, 4))[:, ::2],
             rng.normal(size=(5, 2)).astype(np.float32),
             np.arange(6).reshape(3, 2), [[1.0, 2.0]], np.zeros((3,)),
             np.zeros((2, 3)), "points", None]
    with_bad = rng.normal(size=(40, 2))
    with_bad[rng.integers(40, size=6), rng.integers(2, size=6)] = [
        np.nan, np.inf, -np.inf, np.nan, 1e308, -0.0]
    cases.append(with_bad)
    for points in cases:
        kept, dropped, check = safety.check_points(points)
        try:
            array = np.asarray(points, dtype=float)
        except (TypeError, ValueError):
            array = np.zeros(0)
        if array.ndim != 2 or array.shape[1:] != (2,):
            assert check.reason is Reason.MALFORMED
            assert kept.shape == (0, 2) and dropped == 0
            continue
        rows = [i for i in range(len(array))
                if all(math.isfinite(x) for x in array[i])]
        assert check.valid
        assert kept.dtype == np.float64
        np.testing.assert_array_equal(kept, array[rows])
        assert dropped == len(array) - len(rows)
        if isinstance(points, np.ndarray) and points.dtype == np.float64 \
                and dropped == 0:
            assert kept is points  # read, not copied


def test_next_status_matches_the_fields():
    rng = np.random.default_rng(5)
    for _ in range(200):
        status = rng.normal(size=len(STATUS_FIELDS))
        status[F["stopped"]] = float(rng.random() < 0.5)
        after = safety.StopState(bool(rng.random() < 0.5), rng.random())
        fault = None
        if rng.random() < 0.5:
            value = rng.choice([np.nan, np.inf, -np.inf, rng.normal()])
            fault = (int(rng.integers(5)), safety.InputCheck(
                Reason(int(rng.integers(1, 5))), int(rng.integers(6)),
                float(value)))
        dropped = int(rng.integers(4))
        new = safety.next_status(status, fault, after, dropped)
        assert new is not status
        assert new[F["stopped"]] == float(after.stopped)
        assert new[F["invalid"]] == float(fault is not None)
        assert new[F["valid_time"]] == after.valid_time
        assert new[F["dropped_points"]] == dropped
        tripped = after.stopped and status[F["stopped"]] < 0.5
        assert new[F["trips"]] == status[F["trips"]] + tripped
        detail = [F[name] for name in ("reason", "input", "entry", "value")]
        if fault is not None:
            value = fault[1].value
            stored = 0.0 if math.isnan(value) else (
                math.copysign(1e308, value) if math.isinf(value) else value)
            np.testing.assert_array_equal(new[detail], [
                int(fault[1].reason), fault[0], fault[1].entry, stored])
        elif not after.stopped:
            np.testing.assert_array_equal(new[detail], [0, -1, -1, 0])
        else:
            np.testing.assert_array_equal(new[detail], status[detail])


def test_guard_still_linearises():
    guard = InputGuard([GuardedInput("u", 3), GuardedInput(
        "v", 2, (("v", [1.0, 2.0]),), zero_when_stopped=True)],
        time_step=H)
    context = guard.CreateDefaultContext()
    guard.GetInputPort("u").FixValue(context, [0.1, 0.2, 0.3])
    guard.GetInputPort("v").FixValue(context, [0.4, 0.5])
    # (The status' valid time grows each tick: not an equilibrium.)
    linear = Linearize(guard, context, input_port_index=InputPortIndex(0),
                       output_port_index=OutputPortIndex(0),
                       equilibrium_check_tolerance=math.inf)
    np.testing.assert_array_equal(linear.D(), np.eye(3))
    np.testing.assert_array_equal(linear.B()[:3], np.eye(3))
    np.testing.assert_array_equal(linear.A(), np.zeros((14, 14)))


def following_guard():
    return InputGuard([GuardedInput("q", 3, follows=Following(
        "q_command", 0.1, "rad", "it does not follow")), GuardedInput(
        "u", 1)], time_step=H, params=SafetyParameters(hold_time=HOLD))


@pytest.mark.parametrize("autodiff", [False, True])
def test_a_followed_input_trips_beyond_its_tolerance(autodiff):
    """An input that follows a command: valid within the tolerance of it
    (and passed on, a true measurement, also when not), a fault beyond
    it from the second tick on (at the first no command was sent yet),
    not checked during the stop, which clears after the hold time with
    `resume` at that tick alone; in double and in AutoDiffXd."""
    guard = following_guard()
    if autodiff:
        guard = guard.ToAutoDiffXd()
    context = guard.CreateDefaultContext()
    command = np.array([0.3, -0.2, 1.0])
    guard.GetInputPort("u").FixValue(context, [0.0])

    def tick(q, expected_stop, expected_resume=0.0):
        guard.GetInputPort("q").FixValue(context, np.asarray(q))
        guard.GetInputPort("q_command").FixValue(context, command)
        outputs = [float(ExtractValue(np.asarray(
            guard.GetOutputPort(name).Eval(context), dtype=object))[0, 0])
            for name in ("stop", "resume")]
        assert outputs == [expected_stop, expected_resume]
        np.testing.assert_array_equal(ExtractValue(np.asarray(
            guard.GetOutputPort("q").Eval(context), dtype=object)).ravel(),
            q)
        context.SetDiscreteState(guard.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector())

    far = command + [0.0, 0.1001, 0.0]
    tick(far, 0.0)                          # the first tick: unchecked
    tick(command + [0.09, -0.09, 0.05], 0.0)  # within it
    tick(far, 1.0)
    status = ExtractValue(np.asarray(guard.GetOutputPort(
        "safety_status").Eval(context), dtype=object)).ravel()
    assert status[F["reason"]] == int(Reason.NOT_FOLLOWING)
    assert (status[F["input"]], status[F["entry"]]) == (0, 1)
    assert status[F["value"]] == pytest.approx(0.1001)
    assert guard.reason(context) == (
        "q[1] is 0.1 rad from the last command (tolerance 0.1 rad): it "
        "does not follow")
    for _ in range(round(HOLD / H) - 1):
        tick(far, 1.0)                      # held, but not kept stopped
    tick(far, 0.0, 1.0)                     # clears: resume
    tick(command, 0.0)
    tick(far, 1.0)


def test_a_guard_with_a_followed_input_still_linearises():
    guard = following_guard()
    context = guard.CreateDefaultContext()
    guard.GetInputPort("q").FixValue(context, [0.1, 0.2, 0.3])
    guard.GetInputPort("q_command").FixValue(context, [0.1, 0.2, 0.3])
    guard.GetInputPort("u").FixValue(context, [0.0])
    linear = Linearize(guard, context, input_port_index=InputPortIndex(0),
                       output_port_index=OutputPortIndex(0),
                       equilibrium_check_tolerance=math.inf)
    np.testing.assert_array_equal(linear.D(), np.eye(3))


def test_a_follow_tolerance_that_is_not_positive_is_refused():
    with pytest.raises(ValueError, match=(
            r"q follows.tolerance = 0.0 is not allowed: must be greater "
            r"than 0")):
        InputGuard([GuardedInput("q", 3, follows=Following("c", 0.0))])


def test_check_following_in_closed_form():
    assert safety.check_following([1.0, 2.0], [1.05, 1.91], 0.1).valid
    assert safety.check_following([1.0, 2.0, 3.0], [1.0, 2.3, 2.5], 0.1) == (
        Reason.NOT_FOLLOWING, 1, pytest.approx(-0.3))
    assert safety.check_following(InitializeAutoDiff([0.0, 0.5]).ravel(),
                                  np.zeros(2), 0.4) == (
        Reason.NOT_FOLLOWING, 1, 0.5)


@pytest.mark.parametrize("lower, upper, message", [
    ([0.0, 1.0], 2.0, r"lower = \[0.0, 1.0\] is not allowed: must be a "
     r"number or 3 numbers"),
    ([0.0, 3.0, 0.0], [1.0, 2.0, 1.0], r"lower = .* must be at most upper"),
    (float("nan"), 1.0, r"lower = nan is not allowed"),
])
def test_a_guarded_inputs_range_that_is_not_one_is_refused(lower, upper,
                                                            message):
    with pytest.raises(ValueError, match=message):
        InputGuard([GuardedInput("u", 3, lower=lower, upper=upper)])
