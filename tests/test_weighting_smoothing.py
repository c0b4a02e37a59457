"""The deactivation strategy of Sec. IV-C with hysteresis and a rate limit
(drake_wbc.math.workspace, the WorkspaceAdapter stage): the rate limit's
closed form, the hysteresis keeping its side, the base taking over outside
the workspace, no lock at the boundary; the stage's state, scalar
conversion and linearisation; its parameters' checks; and, in closed loop,
the jumps of sigma counted: the paper's rule jumps 0 <-> 1 where the hand
lets go at the boundary, ours changes by at most max_rate * time_step a
tick, in every scenario."""

import math

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractValue
from pydrake.systems.primitives import Linearize

from drake_wbc.controller.parameters import load_controller_parameters
from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import (
    find_scenario,
    load_scenario,
    scenario_files,
)
from drake_wbc.math import workspace
from drake_wbc.math.workspace import (
    WEIGHTING_START,
    WorkspaceAdapterParameters,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages import WorkspaceAdapter
from drake_wbc.station.scene import HandForce

UPPER, LOWER = 0.04, 0.035
C_M = 0.06
"""Far above the band: f depends on the workspace alone."""
OUTSIDE = np.array([0.85, 0.0, 0.3])
"""d = 0.85 m > d^u (T_a = T_b here): P_d = 0, its slope 0, so f_xy = 0
and grad C_m^d = 0: only the test d_dot < 0 can lead back."""
INSIDE = np.array([0.6, 0.0, 0.3])
SPEED, STEP = 0.02, 0.1
"""The defaults: deactivation_speed (m/s) and max_rate h at 100 Hz."""


def twist(vx=0.0, vy=0.0):
    return np.array([vx, vy, 0.0, 0.0, 0.0, 0.0])


def tick(previous, V, p=OUTSIDE, speed=SPEED, max_step=STEP):
    """(sigma_xy, sigma_phi, deactivated_xy, deactivated_phi) one tick on."""
    s = workspace.local_workspace_state(
        p, V, C_M, np.zeros(6), UPPER, LOWER, previous=previous,
        deactivation_speed=speed, max_step=max_step)
    return np.array([s.sigma_xy, s.sigma_phi, s.deactivated_xy,
                     s.deactivated_phi])


def run(previous, twists, **kwargs):
    states = [np.asarray(previous, dtype=float)]
    for V in twists:
        states.append(tick(states[-1], V, **kwargs))
    return np.array(states)


# --- the math ----------------------------------------------------------------

@pytest.mark.parametrize("max_step", [0.05, 0.07, 0.3])
def test_the_rate_limit_has_its_closed_form(max_step):
    """sigma_k = max(f, 1 - k Delta) falling (the motion leads out) and
    min(1, k Delta) rising (it leads back), Delta = max_rate h; the last
    step lands on the target."""
    k = np.arange(41)
    out = run(WEIGHTING_START, [twist(0.1)] * 40, max_step=max_step)
    np.testing.assert_allclose(out[:, 0], np.maximum(0.0, 1.0 - k * max_step),
                               rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out[:, 1], 1.0)  # phi = 0: f_phi = 1
    back = run((0.0, 1.0, 0.0, 0.0), [twist(-0.1)] * 40, max_step=max_step)
    np.testing.assert_allclose(back[:, 0], np.minimum(1.0, k * max_step),
                               rtol=0, atol=1e-12)
    assert np.all(np.abs(np.diff(out[:, :2], axis=0)) <= max_step + 1e-15)


def test_without_hysteresis_and_limit_the_factors_are_the_papers_rule():
    rng = np.random.default_rng(2020)
    for _ in range(300):
        radius, azimuth = rng.uniform(0.5, 0.9), rng.uniform(-1.0, 1.0)
        p = np.array([radius * np.cos(azimuth), radius * np.sin(azimuth),
                      0.3])
        V, g = rng.normal(size=6) * 0.1, rng.normal(size=6) * 0.01
        C_m = rng.uniform(0.03, 0.07)
        s = workspace.local_workspace_state(p, V, C_m, g, UPPER, LOWER)
        grad_d, grad_phi = (workspace.extent_gradient(p),
                            workspace.deflection_gradient(p))
        c = s.capability
        assert s.sigma_xy == workspace.deactivated(s.f_xy, c.gradient_d, V,
                                                   grad_d)
        assert s.sigma_phi == workspace.deactivated(s.f_phi, c.gradient_phi,
                                                    V, grad_phi)


def test_hysteresis_keeps_the_side():
    outside_base = (0.0, 1.0, 0.0, 0.0)  # f_xy = 0, not deactivated
    deactivated = (1.0, 1.0, 1.0, 1.0)
    # Leading back slower than v_h does not deactivate (the paper's rule,
    # v_h = 0, does at once).
    slow_back = run(outside_base, [twist(-0.5 * SPEED)] * 30)
    np.testing.assert_array_equal(slow_back[:, [0, 2]], 0.0)
    assert tick(outside_base, twist(-0.5 * SPEED), speed=0.0)[2] == 1.0
    # Once deactivated, at rest, leading back slowly, or along the
    # boundary (d_dot = 0), the side and sigma stay.
    for V in (twist(), twist(-0.5 * SPEED), twist(vy=0.1)):
        kept = run(deactivated, [V] * 30)
        np.testing.assert_array_equal(kept[:, [0, 2]], 1.0)
    # Noise below v_h in any direction never gives the motion back to
    # the arm, where the paper's rule jumps with it.
    rng = np.random.default_rng(7)
    noise = [np.concatenate([rng.normal(size=3), np.zeros(3)]) for _ in
             range(200)]
    noise = [0.9 * SPEED * n / np.linalg.norm(n) for n in noise]
    ours = run(outside_base, noise)
    np.testing.assert_array_equal(ours[:, 0], 0.0)
    paper = run(outside_base, noise, speed=0.0, max_step=math.inf)
    assert np.count_nonzero(np.abs(np.diff(paper[:, 0])) == 1.0) > 50


def test_the_base_takes_over_outside_as_soon_as_the_motion_leads_out():
    """From the deactivated side, even a push outwards far slower than v_h
    ends the deactivation, and sigma_xy falls to f = 0 within 1 / max_rate:
    the arm alone is never kept in charge beyond the boundary."""
    states = run((1.0, 1.0, 1.0, 1.0), [twist(0.001)] * 30)
    np.testing.assert_array_equal(states[1:, 2], 0.0)
    np.testing.assert_allclose(states[:, 0],
                               np.maximum(0.0, 1.0 - np.arange(31) * STEP),
                               rtol=0, atol=1e-12)
    assert states[-1, 0] == 0.0
    # Inside the workspace f = 1 whatever the side.
    inside = run((1.0, 1.0, 0.0, 0.0), [twist(0.05)] * 5, p=INSIDE)
    np.testing.assert_array_equal(inside[:, :2], 1.0)


def test_the_robot_never_locks_at_the_boundary():
    """Outside the workspace with the base in charge (sigma_xy = 0), a hand
    leading the tool back: the arm takes the motion over at max_rate and
    carries it back inside. While outside d^u, the arm's travel is the
    closed form v h sum_k min(1, k Delta) (the arm carries sigma_xy of the
    planar motion, eq. (weight-factors))."""
    v, h = 0.05, 0.01
    p, state = OUTSIDE.copy(), np.array([0.0, 1.0, 0.0, 0.0])
    travelled = [0.0]
    for _ in range(400):
        state = tick(state, twist(-v), p=p)
        p[0] -= state[0] * v * h
        travelled.append(OUTSIDE[0] - p[0])
        if p[0] < 0.75:
            break
    assert p[0] < 0.75 and state[0] == 1.0  # back inside, the arm's
    k = np.arange(1, 11)
    np.testing.assert_allclose(
        travelled[1:11], v * h * np.cumsum(np.minimum(1.0, k * STEP)),
        rtol=0, atol=1e-12)


def test_the_start_state_and_its_checks():
    assert WEIGHTING_START == (1.0, 1.0, 0.0, 0.0)
    for previous, match in (((1.5, 1, 0, 0), r"previous\[0\] = 1.5"),
                            ((1, 1, 0.5, 0), r"previous\[2\] = 0.5"),
                            ((1, 1, 0), "previous = .* has shape")):
        with pytest.raises(ValueError, match=match):
            tick(previous, twist())
    with pytest.raises(ValueError, match="deactivation_speed = -1.0"):
        tick(WEIGHTING_START, twist(), speed=-1.0)
    with pytest.raises(ValueError, match="max_step = 0.0"):
        tick(WEIGHTING_START, twist(), max_step=0.0)


# --- the parameters ----------------------------------------------------------

@pytest.mark.parametrize("fields, match", [
    (dict(deactivation_speed=-0.01), "deactivation_speed = -0.01"),
    (dict(deactivation_speed=float("nan")), "deactivation_speed = nan"),
    (dict(max_rate=0.0), "max_rate = 0.0 is not allowed: must be greater"),
    (dict(max_rate=float("inf")), "max_rate = inf is not allowed"),
])
def test_the_parameters_are_checked_where_they_enter(fields, match):
    with pytest.raises(ValueError, match=match):
        WorkspaceAdapterParameters(**fields)


def test_the_yaml_names_the_field():
    params = load_controller_parameters(
        text="workspace: {deactivation_speed: 0.05, max_rate: 8.0}\n")
    assert (params.workspace.deactivation_speed,
            params.workspace.max_rate) == (0.05, 8.0)
    with pytest.raises(ValueError, match="workspace.max_rate = -2.0"):
        load_controller_parameters(text="workspace: {max_rate: -2.0}\n")
    defaults = WorkspaceAdapterParameters()
    assert (defaults.deactivation_speed, defaults.max_rate) == (SPEED, 10.0)


# --- the stage ---------------------------------------------------------------

ARM = ArmKinematics()
PHRI = WorkspaceAdapterParameters(mode="intuitive-phri")


def adapter_context(system, p_a, V_a, previous=WEIGHTING_START):
    """A context of `system` with its inputs at p_a, V_a (given in T_a)
    and its state `previous`."""
    R, origin = system.R_ba, system.arm_base_position
    context = system.CreateDefaultContext()
    values = (R @ p_a + origin, np.concatenate([R @ V_a[:3], R @ V_a[3:]]),
              [C_M], np.zeros(6))
    names = ("end_effector_position", "end_effector_velocity",
             "capability", "capability_gradient")
    for name, value in zip(names, values, strict=True):
        system.GetInputPort(name).FixValue(context,
                                           np.asarray(value, dtype=float))
    context.SetDiscreteState(np.asarray(previous, dtype=float))
    return context


def sigmas_of(system, context):
    return np.array([system.GetOutputPort(name).Eval(context)[0]
                     for name in ("sigma_xy", "sigma_phi")])


def test_the_stage_steps_its_state_to_what_it_outputs():
    system = WorkspaceAdapter(PHRI, ARM, time_step=0.01)
    assert system.num_discrete_state_groups() == 1
    np.testing.assert_array_equal(
        system.CreateDefaultContext().get_discrete_state_vector()
        .CopyToVector(), WEIGHTING_START)
    context = adapter_context(system, OUTSIDE, twist(0.1))
    expected = [1.0]
    for _ in range(25):
        output = sigmas_of(system, context)
        update = system.EvalUniquePeriodicDiscreteUpdate(context).value()
        np.testing.assert_array_equal(update[:2], output)
        context.SetDiscreteState(update)
        expected.append(max(0.0, expected[-1] - STEP))
        assert output[0] == pytest.approx(expected[-1], abs=1e-12)
    assert output[0] == 0.0
    # A longer period is a larger step: max_rate * time_step.
    slow = WorkspaceAdapter(PHRI, ARM, time_step=0.04)
    assert sigmas_of(slow, adapter_context(slow, OUTSIDE, twist(0.1)))[0] \
        == pytest.approx(0.6, abs=1e-12)


def test_the_pHRI_stage_needs_a_period():
    with pytest.raises(ValueError, match="time_step = 0.0"):
        WorkspaceAdapter(PHRI, ARM, time_step=0.0)
    WorkspaceAdapter(WorkspaceAdapterParameters(), ARM, time_step=0.0)


def test_the_stage_converts_and_linearizes():
    """Linearize of the stage alone (not at an equilibrium: the tick's
    map is what is linearised): where the rate limit holds sigma_xy
    (falling from 1 towards f = 0) its next value is the previous one plus
    a constant step, d sigma+ / d sigma = 1 and no input reaches it; where
    sigma_xy follows f on its ramp (d in the band of f) d sigma+ / d sigma
    = 0 and it depends on the position."""
    system = WorkspaceAdapter(PHRI, ARM)
    converted = system.ToAutoDiffXd()
    context = adapter_context(system, OUTSIDE, twist(0.1))
    ad_context = converted.CreateDefaultContext()
    ad_context.SetTimeStateAndParametersFrom(context)
    for i in range(system.num_input_ports()):
        value = system.get_input_port(i).Eval(context)
        converted.get_input_port(i).FixValue(
            ad_context, np.array([AutoDiffXd(x) for x in value]))
    np.testing.assert_array_equal(
        ExtractValue(sigmas_of(converted, ad_context)).ravel(),
        sigmas_of(system, context))
    limited = Linearize(system, context,
                        equilibrium_check_tolerance=math.inf)
    np.testing.assert_allclose(limited.A()[0], [1, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(limited.B()[0], 0.0, atol=1e-12)
    # On the ramp of f_xy (C_m^d = C_m P_d within the band), from the
    # state it has reached there: sigma_xy = f_xy, a function of p.
    d = 0.7705
    ramp = workspace.local_workspace_state(
        system.R_ba @ np.array([d, 0, 0.3]) + system.arm_base_position,
        np.zeros(6), C_M, np.zeros(6), UPPER, LOWER, R_ba=system.R_ba,
        arm_base_in_base=system.arm_base_position)
    assert 0.1 < ramp.f_xy < 0.9
    on_ramp = adapter_context(system, np.array([d, 0, 0.3]), twist(0.01),
                              previous=(ramp.f_xy, 1.0, 0.0, 0.0))
    linear = Linearize(system, on_ramp,
                       equilibrium_check_tolerance=math.inf)
    np.testing.assert_allclose(linear.A()[0], 0.0, atol=1e-12)
    assert np.abs(linear.B()[0, :3]).max() > 10.0  # f is steep in d


# --- closed loop: the jumps counted -----------------------------------------

H = 0.01
"""The scenarios' control period (s)."""


def boundary_scenario(**workspace_fields):
    """`phri` shortened to what made sigma chatter: the hand pushes the
    tool out to the workspace's boundary (3 N along x from 0.5 to 2.5 s),
    lets go there, and pulls it back (4 N from 4.5 to 6 s)."""
    scenario = load_scenario(find_scenario("phri"))
    scenario.duration = 7.0
    scenario.scene.hand = HandForce(
        times=[0.5, 1.0, 2.5, 3.0, 4.5, 5.0, 6.0, 6.5],
        forces=[[0, 0, 0], [3, 0, 0], [3, 0, 0], [0, 0, 0], [0, 0, 0],
                [-4, 0, 0], [-4, 0, 0], [0, 0, 0]])
    for name, value in workspace_fields.items():
        setattr(scenario.controller.workspace, name, value)
    return scenario


def sigma_steps(log):
    return np.abs(np.diff(np.concatenate(
        [log["sigma_xy"], log["sigma_phi"]], axis=1), axis=0))


@pytest.fixture(scope="module")
def boundary_runs():
    return {name: simulate(build_closed_loop(boundary_scenario(**fields)))
            for name, fields in (
                ("ours", {}),
                ("paper", dict(deactivation_speed=0.0, max_rate=1.0 / H)))}


def test_the_papers_rule_jumps_at_the_boundary_and_ours_does_not(
        boundary_runs):
    paper, ours = (sigma_steps(boundary_runs[name]) for name in
                   ("paper", "ours"))
    assert np.count_nonzero(paper > 0.5) >= 5
    assert ours.max() <= 10.0 * H + 1e-12
    # The meaning is kept: the base takes over out there (sigma_xy = 0
    # while the hand pushes out) and the arm when the hand pulls back.
    log = boundary_runs["ours"]
    t, sigma_xy = log.time, log["sigma_xy"][:, 0]
    assert sigma_xy[(t > 2.0) & (t < 2.5)].max() == 0.0
    assert sigma_xy[(t > 5.5) & (t < 6.0)].min() == 1.0


@pytest.mark.parametrize("path", scenario_files(), ids=lambda p: p.stem)
def test_in_every_scenario_sigma_changes_by_at_most_the_stated_step(path):
    scenario = load_scenario(path)
    scenario.duration = 0.3
    log = simulate(build_closed_loop(scenario))
    params = scenario.controller
    bound = params.workspace.max_rate * params.time_step
    if params.workspace.mode != "intuitive-phri":
        bound = 0.0
    assert sigma_steps(log).max() <= bound + 1e-12
