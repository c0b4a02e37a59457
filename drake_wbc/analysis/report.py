"""`drake-wbc bode`: every frequency response of a scenario, written out.

For a scenario's controller and station, at its initial arm
configuration (drake_wbc.analysis.chains), this computes and writes (PNG
and CSV per figure, summary.csv, and the table it returns):

- base_filter: BaseVelocityFilter linearised, discrete at the control
  period and continuous, over eq. (filtering)'s closed forms;
- split_ideal: V_ee (x of T_b) to the base's share, the arm's share and
  their sum with ideal actuators (flat at 0 dB and 0 degrees while
  alpha = 0), the base's share over k_b times eq. (filtering);
- split_base_loop: the same with the station's BaseVelocityDriver, and
  the driver alone; where the end effector's command stops being
  reproduced (|sum - 1| > REPRODUCTION_TOLERANCE); and with the
  station's plant after the driver (its base servo, the flexible
  mount): the base's actual velocity and the end effector's;
- base_plant: the base's velocity command to its actual velocity and to
  the end effector's, through the driver and the plant (the servo and
  the mount's rocking mode), over the driver alone;
- dmp_force: the coupled DMPs' force-to-position responses, discrete at
  the control period, over the exact zero-order-hold equivalents of
  eqs. (lp-admit) and (tf-admit);
- contact_loops: the arm's CDMP against a contact spring K (the wiping
  pad's), with the loops' gain and phase margins: the DMP alone, and
  with the READING_TO_MOTION_PERIODS from a reading to the arm's motion
  (the real loop's margins lie between these two);
- filter_sweep, split_sweep: families of curves over omega_f and zeta;
- admittance_loop_*: in a scenario with intuitive pHRI (S_hri = 1 in its
  parameters or its task) or a hand on the tool, the admittance loop of
  drake_wbc.analysis.admittance_loop per case (the scenario's hand and a
  stiff one, with and without the estimator's inertia compensation, at
  the scenario's hri_time_constant and at the paper's 0 if that is not
  it): L per translational axis of T_b, and a row per case with the gain
  and phase margins of its least stable axis and the largest stable
  k_hri of the whole loop; a case whose open loop is unstable has no
  margins (n/a, with its unstable pole in the notes).
"""

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from drake_wbc.analysis import (
    admittance_loop,
    chains,
    closed_forms,
    plant_chain,
)
from drake_wbc.analysis.bode import (
    BodePlot,
    draw,
    format_table,
    summarize,
    write_csv,
    write_summary_csv,
)
from drake_wbc.analysis.dmp_force_response import linearize_dmp_force
from drake_wbc.analysis.frequency import (
    frequency_grid,
    linear_system_response,
    stability_margins,
)
from drake_wbc.experiments.scenario import controller_arm, scenario_station
from drake_wbc.math import distribution, kinematics
from drake_wbc.math.filtering import (
    lowpass_response,
    lowpass_zoh_response,
)
from drake_wbc.math.validation import positive, whole_number

CONTACT_STIFFNESS = 3.0e3
"""K of the contact loops, N/m: a soft sponge pressed against a wall
(about 3e3 N/m, as the shipped wiping pad's; `compute_bode_report`
takes another)."""

READING_TO_MOTION_PERIODS = (2, 3)
"""d, control periods from a wrist reading to the arm's motion beyond
the coupled DMP's own, that the contact loops' delayed rows add as
z^-d (the row without them is the DMP alone): the wrist sensor's sample
and the arm driver's ramp over one command period make two, the arm's
servo up to one more. The station's plant part
(drake_wbc.analysis.admittance_loop.linearize_plant_part) shows it: the
arm at 46 % of a command one period after it and at 101 % after two,
the wrist's reading one period behind the arm. The force loop K k_f h
z^-d / (z - 1) is stable below K k_f h = 0.618 (d = 2) and 0.445
(d = 3), against 2 for the DMP alone (as the shipped tool's model says
of its pad)."""

REPRODUCTION_TOLERANCE = 0.1
"""|V_ee,actual / V_ee - 1| above which the end effector's command counts
as no longer reproduced (10 %)."""

SWEEP_OMEGA_F_HZ = (0.5, 1.0, 2.0, 4.0)
SWEEP_ZETA = (0.5, 0.707, 1.0)
"""The family of filter settings drawn in filter_sweep and split_sweep."""

AXIS = 0
"""The end-effector axis of the split figures: x of T_b."""

PLANT_CURVE = "end effector with the base loop and the plant"
"""The curve (and row) of the end effector's actual velocity per V_ee
through the base's loop and the station's plant (an ideal arm)."""


@dataclass
class BodeReport:
    """What `write_bode_report` wrote.

    Attributes:
        plots: the BodePlots, by name.
        rows: the table's ResponseSummary rows.
        table: the table as text.
        notes: lines printed under the table.
        paths: the files written.
    """

    plots: dict = field(default_factory=dict)
    rows: list = field(default_factory=list)
    table: str = ""
    notes: list = field(default_factory=list)
    paths: list = field(default_factory=list)


def base_share_gain(point, axis=AXIS):
    """k_b: the base's share of V_ee along `axis` at DC, (J_b V_b)_axis
    for a unit V_ee on that axis, from the math layer's eq. (wbccm)
    (drake_wbc.math.distribution, k_n = 0, J_wb with the arm's mounting
    ^bR_a); `axis` 0 to 5."""
    axis = whole_number("axis", axis)
    if axis > 5:
        raise ValueError(f"axis = {axis!r} is not allowed: must be 0 to 5 "
                         "(an entry of the twist [v; w])")
    J_b = kinematics.base_jacobian(point.end_effector_position)
    J_wb = kinematics.whole_body_jacobian(None, point.end_effector_position,
                                          point.arm.R_ba)
    V_wb = distribution.distribute(J_wb, np.eye(6)[axis], point.sigma_xy,
                                   point.sigma_phi)
    return float((J_b @ V_wb[6:])[axis])


def first_departure(hertz, response, tolerance=REPRODUCTION_TOLERANCE):
    """The lowest frequency (Hz) at which |response - 1| exceeds
    `tolerance`, or nan."""
    tolerance = positive("tolerance", tolerance)
    off = np.nonzero(np.abs(np.asarray(response) - 1.0) > tolerance)[0]
    return float(hertz[off[0]]) if len(off) else float("nan")


def _split_plots(report, params, point, station, hertz, omega, h):
    rows = report.rows
    ideal = linear_system_response(chains.linearize_split(params, point),
                                   omega)
    k_b = base_share_gain(point)
    f = params.base_filter
    plot = BodePlot("split_ideal", "V_ee (x) split, ideal actuators "
                    f"(sigma_xy = {point.sigma_xy:g}, alpha = "
                    f"{point.alpha:g})", hertz, nyquist_hz=0.5 / h)
    labels = ("base share J_b V_b^flt", "arm share R_ba V_a^ref",
              "sum: end effector")
    for i, label in enumerate(labels):
        response = ideal[:, 6 * i + AXIS, AXIS]
        plot.add(label, response)
        rows.append(summarize(f"split: {label}", hertz, response))
    plot.add(f"k_b = {k_b:.3f} x eq. (filtering), ZOH", k_b
             * lowpass_zoh_response(f.omega_f, f.zeta, h, omega), True)
    report.plots[plot.name] = plot

    driver, step = station.options.base, station.options.time_step
    real = linear_system_response(chains.linearize_split(
        params, point, base_driver=driver, base_step=step), omega)
    loop = chains.linearize_base_driver(driver, step)
    plot = BodePlot("split_base_loop", "V_ee (x) split with the base's "
                    f"velocity loop (lag {driver.lag:g} s)", hertz,
                    nyquist_hz=0.5 / h)
    for i, label in enumerate(("base share J_b v_base",
                               "arm share R_ba V_a^ref",
                               "sum: end effector")):
        response = real[:, 6 * i + AXIS, AXIS]
        plot.add(label, response)
        rows.append(summarize(f"with base loop: {label}", hertz, response))
    plot.add("base velocity loop alone",
             linear_system_response(loop, omega)[:, AXIS, AXIS])
    rows.append(summarize("base velocity loop alone", hertz,
                          plot.curves[-1].response))
    plot.add("sum with an ideal base", ideal[:, 12 + AXIS, AXIS], True)
    plant = linear_system_response(
        chains.linearize_split(params, point, station=station), omega)
    for row, label in ((18, "base loop and plant: base velocity"),
                       (21, PLANT_CURVE)):
        plot.add(label, plant[:, row + AXIS, AXIS])
        rows.append(summarize(label, hertz, plot.curves[-1].response))
    report.plots[plot.name] = plot
    _base_plant_plot(report, station, loop, hertz, omega, h)
    departure = first_departure(hertz, real[:, 12 + AXIS, AXIS])
    where = ("nowhere on the band" if np.isnan(departure)
             else f"from {departure:.3f} Hz")
    report.notes.append(
        "end effector with the base's velocity loop: |V_ee,actual / V_ee - "
        f"1| exceeds {REPRODUCTION_TOLERANCE:g} {where} (largest "
        f"{np.abs(real[:, 12 + AXIS, AXIS] - 1).max():.3f})")
    departure = first_departure(hertz, plant[:, 21 + AXIS, AXIS])
    where = ("nowhere on the band" if np.isnan(departure)
             else f"from {departure:.3f} Hz")
    report.notes.append(
        f"{PLANT_CURVE}: |V_ee,actual / V_ee - 1| exceeds "
        f"{REPRODUCTION_TOLERANCE:g} {where} (largest "
        f"{np.abs(plant[:, 21 + AXIS, AXIS] - 1).max():.3f})")
    report.notes.append(
        "end effector with ideal actuators: largest |sum - 1| = "
        f"{np.abs(ideal[:, 12:18, :] - np.eye(6)).max():.2e}")


def _base_plant_plot(report, station, loop, hertz, omega, h):
    """base_plant: the base's command (x of T_b, held over the control
    period h) to its actual velocity and the end effector's through the
    driver and the plant, over the driver alone."""
    plant = linear_system_response(plant_chain.linearize_base_plant(station, h),
                                   omega)
    plot = BodePlot("base_plant", "base velocity command (x) through the "
                    "base's loop and the plant (servo, mount)", hertz,
                    nyquist_hz=0.5 / h)
    for row, label in ((AXIS, "base velocity, driver and plant"),
                       (3 + AXIS, "end effector, driver and plant")):
        plot.add(label, plant[:, row, AXIS])
        report.rows.append(summarize(label, hertz, plant[:, row, AXIS]))
    plot.add("base velocity loop alone (plant step)",
             linear_system_response(loop, omega)[:, AXIS, AXIS], True)
    report.plots[plot.name] = plot


def _dmp_plots(report, params, hertz, omega, h, stiffness):
    arm, dmp = params.arm_cdmp, params.arm_cdmp.dmp
    plot = BodePlot("dmp_force", "coupled DMPs: force to position (m/N), "
                    f"discrete at {h:g} s", hertz, nyquist_hz=0.5 / h)
    responses = {}
    for kind, label in (("stiffness", "arm CDMP, stiffness axis"),
                        ("admittance", "arm CDMP, force axis"),
                        ("phri", "whole-body CDMP, S_hri = 1")):
        responses[kind] = linearize_dmp_force(kind, params).response(omega)
        plot.add(label, responses[kind])
        report.rows.append(summarize(label, hertz, responses[kind]))
    # The closed forms' exact zero-order-hold equivalents, as the stages
    # run at h: the continuous forms part from them by the hold's half
    # period of delay (18 degrees at 10 Hz at h = 0.01 s).
    plot.add("eq. (lp-admit), ZOH", closed_forms.lp_admit_zoh_response(
        arm.k_p, arm.k_d, dmp.tau, dmp.alpha_z, dmp.resolved_beta_z, h,
        omega, velocity_scale=1.0), True)
    for name, gain in (("k_f", arm.k_f),
                       ("k_hri", params.whole_body_cdmp.k_hri)):
        if gain > 0.0:
            plot.add(f"eq. (tf-admit), D_a = {name}, ZOH",
                     closed_forms.tf_admit_zoh_response(gain, h, omega),
                     True)
    report.plots[plot.name] = plot

    plot = BodePlot("contact_loops", f"arm CDMP against a contact of "
                    f"{stiffness:g} N/m: loop K H(z) z^-d", hertz,
                    nyquist_hz=0.5 / h)
    for kind in ("admittance", "stiffness"):
        linear = linearize_dmp_force(kind, params)
        for delay in (0, *READING_TO_MOTION_PERIODS):

            def loop(w, linear=linear, delay=delay):
                w = np.atleast_1d(w)
                return (stiffness * linear.response(w)
                        * np.exp(-1j * delay * w * h))[0]

            response = stiffness * responses[kind] * np.exp(
                -1j * delay * omega * h)
            label = (f"{kind} axis, DMP alone, no delay" if delay == 0
                     else f"{kind} axis, {delay} periods to motion")
            plot.add(label, response)
            report.rows.append(summarize(
                f"contact loop, {label}", hertz, response,
                stability_margins(loop, omega, h)))
    report.plots[plot.name] = plot


def _sweep_plots(report, params, point, station, hertz, omega, h):
    driver, step = station.options.base, station.options.time_step
    filters = BodePlot("filter_sweep", "base filter, eq. (filtering), "
                       f"discrete at {h:g} s: omega_f and zeta", hertz,
                       nyquist_hz=0.5 / h)
    split = BodePlot("split_sweep", "end effector with the base's velocity "
                     "loop: omega_f and zeta", hertz, nyquist_hz=0.5 / h)
    styles = ("-", "--", ":", "-.")
    for i, f_hz in enumerate(SWEEP_OMEGA_F_HZ):
        for j, zeta in enumerate(SWEEP_ZETA):
            family = (i, styles[j % len(styles)])
            setting = replace(params.base_filter, omega_f=2 * np.pi * f_hz,
                              zeta=zeta, enabled=True)
            label = f"f = {f_hz:g} Hz, zeta = {zeta:g}"
            filters.add(label, linear_system_response(
                chains.linearize_base_filter(setting, h), omega)[:, 0, 0],
                family=family)
            swept = replace(params, base_filter=setting)
            split.add(label, linear_system_response(chains.linearize_split(
                swept, point, base_driver=driver, base_step=step),
                omega)[:, 12 + AXIS, AXIS],
                family=family)
    report.plots[filters.name] = filters
    report.plots[split.name] = split


def has_admittance_loop(scenario):
    """Whether `scenario` runs the intuitive pHRI mode (S_hri = 1 in its
    controller's parameters or at some time of its task) or has a hand on
    the tool: then its bode report has the admittance loops."""
    schedule = scenario.task.phri_switch
    return bool(scenario.controller.phri_switch >= 0.5
                or any(np.max(v) >= 0.5 for v in schedule.values)
                or scenario.scene.hand.times)


def admittance_cases(scenario):
    """The cases of the admittance loops: (name, label, HandImpedance,
    inertia_compensation, hri_time_constant)."""
    own = scenario.scene.hand.impedance or admittance_loop.HandImpedance()
    T = scenario.controller.whole_body_cdmp.hri_time_constant
    cases = []
    for T_case in ((T, 0.0) if T > 0.0 else (T,)):
        for hand_name, hand in (("hand", own),
                                ("stiff", admittance_loop.STIFF_HAND)):
            for inertia in (False, True):
                name = (f"admittance_loop_{hand_name}_T{T_case:g}"
                        f"{'_inertia' if inertia else ''}")
                label = (f"pHRI loop, {hand_name} {hand.stiffness:g} N/m, "
                         f"T = {T_case:g} s"
                         f"{', inertia comp.' if inertia else ''}")
                cases.append((name, label, hand, inertia, T_case))
    return cases


def _admittance_plots(report, scenario, hertz, omega, say):
    """admittance_loop_*: the admittance loop of each case at the
    scenario's k_hri, L per axis of T_b, and its row; linearised where a
    redundant arm's self-motion comes to rest. `say` is told of each
    case as it starts."""
    operating = admittance_loop.operating_scenario(scenario)
    if operating is not scenario:
        settled, start = (np.round(s.station.initial_arm_positions, 3)
                          .tolist() for s in (operating, scenario))
        report.notes.append(
            "pHRI loops linearised where the arm's self-motion comes to "
            f"rest, q_a = {settled} (from {start}; the loop has no "
            "equilibrium while the self-motion moves)")
    scenario = operating
    station = scenario_station(scenario)
    plants = {}
    cases = admittance_cases(scenario)
    for k, (name, label, hand, inertia, T) in enumerate(cases, 1):
        say(f"{label} ({k} of {len(cases)})")
        case = admittance_loop.AdmittanceCase(
            scenario, hand=hand, inertia_compensation=inertia,
            time_constant=T, station=station, plant=plants.get(id(hand)))
        plants[id(hand)] = (case.plant, case.rest_reading)
        result = case.result(label, omega)
        plot, row, note = admittance_summary(name, result, hertz)
        report.plots[name] = plot
        report.rows.append(row)
        report.notes.append(note)


def admittance_summary(name, result, hertz):
    """(BodePlot `name`, its table row, its note) of the admittance
    loop's LoopResult `result` on the grid `hertz` (Hz): L per axis of
    T_b; the row of the axis of the least gain margin, or, where the
    open loop is unstable and the loop has no margins, of the axis of
    the largest gain on the band, its margins n/a and the reason in the
    note."""
    omega = 2.0 * np.pi * np.asarray(hertz)
    axes = admittance_loop.AXES
    limit = admittance_loop.limit_sentence(result, frequency=False)
    plot = BodePlot(name, f"{result.label}: L at k_hri = {result.k_hri:g} "
                    f"({limit})", hertz,
                    nyquist_hz=0.5 / result.loop.time_period())
    for axis in axes:
        plot.add(f"L, {axis} of T_b", result.axis_loop(axis)(omega))
    unavailable = result.margins_unavailable
    if unavailable:
        worst = max(axes, key=lambda a: np.abs(
            plot.curves[axes.index(a)].response).max())
    else:
        worst = min(axes, key=lambda a: result.margins[a].gain_margin)
    row = summarize(f"{result.label} ({worst})", hertz,
                    plot.curves[axes.index(worst)].response,
                    result.margins.get(worst), stable_gain=result.limit,
                    margins_unavailable=unavailable)
    margins = f"; margins n/a, {unavailable}" if unavailable else ""
    note = (f"{result.label}: closed-loop spectral radius "
            f"{result.spectral_radius:.4f} at k_hri = {result.k_hri:g}; "
            f"{admittance_loop.limit_sentence(result)}{margins}")
    return plot, row, note


def compute_bode_report(scenario, points_per_decade=60,
                        contact_stiffness=CONTACT_STIFFNESS, progress=None):
    """Every response of `scenario` (a
    drake_wbc.experiments.scenario.Scenario), on a
    grid from 0.01 Hz to the lower of 100 Hz and the control rate's
    Nyquist frequency; `progress`, if given, is called with a short text
    as each part starts (a pHRI loop takes a few seconds).
    Returns a BodeReport (nothing written)."""
    def say(text):
        if progress is not None:
            progress(text)

    contact_stiffness = positive("contact_stiffness", contact_stiffness)
    say("the base filter and the operating point")
    params = scenario.controller
    h = params.time_step
    hertz, omega = frequency_grid(0.01, min(100.0, 0.5 / h),
                                  points_per_decade)
    point = chains.operating_point(params,
                                   scenario.station.initial_arm_positions,
                                   controller_arm(scenario))
    station = scenario_station(scenario)
    report = BodeReport()
    f = replace(params.base_filter, enabled=True)
    plot = BodePlot("base_filter", "base filter, eq. (filtering): "
                    f"omega_f = {f.omega_f:.4g} rad/s, zeta = {f.zeta:g}",
                    hertz, nyquist_hz=0.5 / h)
    discrete = linear_system_response(chains.linearize_base_filter(f, h),
                                      omega)[:, 0, 0]
    continuous = linear_system_response(chains.linearize_base_filter(
        f, time_step=0.0), omega)[:, 0, 0]
    plot.add(f"BaseVelocityFilter, h = {h:g} s", discrete)
    plot.add("BaseVelocityFilter, continuous", continuous)
    plot.add("eq. (filtering), ZOH", lowpass_zoh_response(
        f.omega_f, f.zeta, h, omega), True)
    plot.add("eq. (filtering)", lowpass_response(f.omega_f, f.zeta, omega),
             True)
    report.plots[plot.name] = plot
    report.rows += [summarize(f"base filter, h = {h:g} s", hertz, discrete),
                    summarize("base filter, continuous", hertz, continuous)]
    say("the split of V_ee, ideal and through the base's loop and plant")
    _split_plots(report, params, point, station, hertz, omega, h)
    say("the coupled DMPs' force responses")
    _dmp_plots(report, params, hertz, omega, h, contact_stiffness)
    say("the sweeps over omega_f and zeta")
    _sweep_plots(report, params, point, station, hertz, omega, h)
    if has_admittance_loop(scenario):
        _admittance_plots(report, scenario, hertz, omega, say)
    report.table = format_table(report.rows)
    report.notes.insert(0, (
        f"operating point: q_a = {np.round(point.arm_positions, 3).tolist()}"
        f", C_m = {point.capability:.4f}, alpha = {point.alpha:g}, "
        f"sigma_xy = {point.sigma_xy:g}, sigma_phi = {point.sigma_phi:g}"))
    return report


def write_bode_report(scenario, output, **options):
    """Computes `compute_bode_report(scenario, **options)` and writes each
    plot's PNG and CSV and summary.csv to the folder `output`. Returns
    the BodeReport, its `paths` filled."""
    report = compute_bode_report(scenario, **options)
    output = Path(output)
    for plot in report.plots.values():
        report.paths += [draw(plot, output), write_csv(plot, output)]
    report.paths.append(write_summary_csv(report.rows,
                                          output / "summary.csv"))
    return report
