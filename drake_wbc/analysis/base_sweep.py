"""Where the base filter helps: the trajectory-tracking step over a grid of
base models (`drake-wbc run <scenario> --sweep`).

Around a trajectory-tracking scenario's station, three small maps, each
varying two of the base's properties and keeping the others the
scenario's:

- `loop`: the velocity loop's lag (1 / natural frequency of a second-order
  loop) against its damping ratio (a first-order lag in the last row);
- `compliance`: the suspension's frequency (rigid in the first column)
  against its damping ratio;
- `acceleration`: the loop's lag against its acceleration limit;
- `wheels`: the horizontal compliance of the wheels on the floor, its
  frequency (rigid wheels in the first column) against its damping ratio
  (drake_wbc.robot.suspension.HorizontalCompliance; around a scenario
  with a suspension only, which carries it).

At each point the scenario runs with and without the filter (its two
variants, full duration) and the point reports the experiment's ratios
without / with filter (drake_wbc.experiments.trajectory_tracking), in the
ground truth and after the paper's measurement processing. The same point
twice (the scenario's own model is in every map) runs once. The plant's
step shrinks to lag / 10 where a short lag needs it.
"""

import copy
import csv
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from drake_wbc.experiments import trajectory_tracking
from drake_wbc.experiments.reports import json_text
from drake_wbc.experiments.runner import build_closed_loop, simulate
from drake_wbc.experiments.scenario import station_base
from drake_wbc.math.validation import validate
from drake_wbc.robot.suspension import (
    HorizontalCompliance,
    SuspensionParameters,
)
from drake_wbc.station.drivers import BaseDriverParameters

RINGING_LAG = 1.0 / (2.0 * np.pi * 3.0)
"""s: the ringing loop's lag (3 Hz natural frequency, BASE_LOOPS)."""

FIRST_ORDER = "first order"
RIGID = "rigid"


@dataclass(frozen=True)
class SweepMap:
    """One map: `x_name` over `x_values` (columns) against `y_name` over
    `y_values` (rows)."""

    name: str
    x_name: str
    x_values: tuple
    y_name: str
    y_values: tuple


MAPS = (
    SweepMap("loop", "loop lag (s)", (0.2, 0.1, RINGING_LAG),
             "loop damping ratio", (FIRST_ORDER, 0.7, 0.3, 0.15, 0.1)),
    SweepMap("compliance", "suspension frequency (Hz)", (RIGID, 3.0, 4.0,
                                                         6.0),
             "suspension damping ratio", (0.3, 0.1, 0.05)),
    SweepMap("acceleration", "loop lag (s)", (0.02, RINGING_LAG, 0.2),
             "loop acceleration limit (m/s^2)", (1.0, 5.0)),
    SweepMap("wheels", "wheels' horizontal frequency (Hz)",
             (RIGID, 5.0, 8.0, 12.0), "wheels' damping ratio",
             (0.2, 0.1, 0.05)),
)
"""The maps of the sweep."""

RATIOS = ("oscillation_rms_mount_band_m_s",
          "oscillation_rms_shaking_band_m_s", "error_rms_total_m_s")
"""The ratios a point reports (ground truth and `measured.`)."""

STEPS = (0.005, 0.002, 0.001)
"""s: plant steps the sweep may use (each divides the control period)."""


def point_scenario(scenario, sweep_map, x, y):
    """A copy of `scenario` with the base of map `sweep_map` at (x, y)."""
    scenario = copy.deepcopy(scenario)
    station = scenario.station
    base = station_base(scenario)
    lag, zeta = base.lag, base.damping_ratio
    accel = list(base.acceleration_limits)
    suspension = station.suspension
    if sweep_map.name == "loop":
        lag, zeta = x, None if y == FIRST_ORDER else y
    elif sweep_map.name == "compliance":
        here = suspension or SuspensionParameters()
        suspension = None if x == RIGID else SuspensionParameters(
            roll_frequency=x, pitch_frequency=x, damping_ratio=y,
            pivot_height=here.pivot_height, horizontal=here.horizontal)
    elif sweep_map.name == "wheels":
        if suspension is None:
            raise ValueError(
                "station.suspension = None is not allowed for the wheels "
                "map: the horizontal compliance is the suspension's")
        suspension = copy.deepcopy(suspension)
        here = suspension.horizontal or HorizontalCompliance()
        suspension.horizontal = None if x == RIGID else HorizontalCompliance(
            frequency=x, yaw_frequency=None, damping_ratio=y,
            drive_inertia=here.drive_inertia,
            drive_yaw_inertia=here.drive_yaw_inertia)
    else:
        lag, accel = x, [y] * 3
    step = next(h for h in STEPS if h <= min(station.time_step, lag / 10))
    station.time_step = step
    station.suspension = suspension
    station.base = BaseDriverParameters(
        lag=lag, damping_ratio=zeta, velocity_limits=base.velocity_limits,
        acceleration_limits=accel,
        servo_time_constant=min(base.servo_time_constant, lag / 4))
    validate(scenario)
    return scenario


def _key(scenario):
    station = scenario.station
    base, suspension = station.base, station.suspension
    horizontal = None if suspension is None else suspension.horizontal
    return (base.lag, base.damping_ratio, tuple(base.acceleration_limits),
            base.servo_time_constant, station.time_step,
            None if suspension is None else (
                suspension.roll_frequency, suspension.pitch_frequency,
                suspension.damping_ratio, suspension.pivot_height),
            None if horizontal is None else (
                tuple(horizontal.frequencies()), horizontal.damping_ratio,
                horizontal.drive_inertia, horizontal.drive_yaw_inertia),
            None if station.traction is None else (
                station.traction.friction_coefficient,
                station.traction.wheel_distance))


def point_ratios(scenario):
    """The ratios (RATIOS, ground truth and `measured.`) of `scenario`
    run with and without the filter."""
    logs = {v.name: simulate(build_closed_loop(scenario, v))
            for v in scenario.variants}
    metrics = trajectory_tracking.compute_metrics(scenario, logs)
    prefix = "ratio_unfiltered_to_filtered."
    return {f"{m}{key}": metrics[f"{prefix}{m}{key}"]
            for m in ("", "measured.") for key in RATIOS}


def check_sweep(scenario, name="duration"):
    """Checks that `scenario` can be swept: a trajectory-tracking
    scenario with the variants `filtered` and `unfiltered`, whose
    duration (`name`: how the command line gives it) reaches past the
    step's start and settling (a shorter one ran every point for
    minutes to give nan ratios only).

    Raises:
        ValueError: naming what is not allowed and why.
    """
    if scenario.experiment != "trajectory_tracking" or {
            v.name for v in scenario.variants} != {"filtered", "unfiltered"}:
        raise ValueError(
            f"experiment = {scenario.experiment!r} is not allowed for a "
            "sweep: must be trajectory_tracking with the variants "
            "filtered and unfiltered")
    shortest = trajectory_tracking.sweep_shortest(scenario)
    if scenario.duration < shortest - 1e-12:
        start, _ = trajectory_tracking.step_window(scenario)
        raise ValueError(
            f"{name} = {scenario.duration!r} is not allowed with --sweep: "
            f"must be at least {shortest:g} s (the step starts at "
            f"{start:g} s and its error counts from "
            f"{trajectory_tracking.SETTLING:g} s later; a shorter run's "
            "ratios are all nan)")


def run_sweep(scenario, output, maps=MAPS, echo=print):
    """Runs the sweep around `scenario` (a trajectory-tracking Scenario
    with `filtered` and `unfiltered` variants) and writes to `output`
    sweep.csv, sweep.json and sweep.png.

    Returns:
        list of dict: one per point (map, x, y and the ratios).
    """
    check_sweep(scenario)
    if scenario.station.suspension is None:
        # The wheels' compliance is the suspension's: no map around a
        # rigid chassis.
        maps = tuple(m for m in maps if m.name != "wheels")
    output = Path(output)
    output.mkdir(parents=True, exist_ok=True)
    points = [(m, x, y) for m in maps for y in m.y_values
              for x in m.x_values]
    done, rows, start = {}, [], time.monotonic()
    for i, (sweep_map, x, y) in enumerate(points):
        point = point_scenario(scenario, sweep_map, x, y)
        key = _key(point)
        if key not in done:
            done[key] = point_ratios(point)
        ratios = done[key]
        rows.append({"map": sweep_map.name, "x": _shown(x), "y": _shown(y),
                     **ratios})
        if echo is not None:
            elapsed = time.monotonic() - start
            left = elapsed / (i + 1) * (len(points) - i - 1)
            echo(f"[{i + 1:2d}/{len(points)}] {sweep_map.name}: "
                 f"{sweep_map.x_name} {_shown(x)}, {sweep_map.y_name} "
                 f"{_shown(y)}: ratio {ratios[_MAIN]:.2f} (measured "
                 f"{ratios['measured.' + _MAIN]:.2f}), total "
                 f"{ratios['error_rms_total_m_s']:.2f}  [{elapsed:.0f} s, "
                 f"about {left:.0f} s left]")
    with open(output / "sweep.csv", "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (output / "sweep.json").write_text(json_text(rows))
    draw_sweep(maps, rows, output / "sweep.png", scenario)
    return rows


_MAIN = "oscillation_rms_shaking_band_m_s"


def _shown(value):
    if isinstance(value, str):
        return value
    return float(f"{value:.3g}")


def draw_sweep(maps, rows, path, scenario):
    """The maps as coloured grids (log colour scale centred on 1, blue:
    the filter helps), each cell labelled with the ground truth's ratio
    and the measured one below it; top row the shaking band (1.5 to 8
    Hz), bottom row the total error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    fig, axes = plt.subplots(2, len(maps), figsize=(5.0 * len(maps), 8.0),
                             squeeze=False, layout="constrained")
    norm = LogNorm(vmin=0.5, vmax=2.0)
    station, base = scenario.station, station_base(scenario)
    low, high = trajectory_tracking.SHAKING_BAND
    for row, (key, title) in enumerate((
            (_MAIN, f"{low:g} to {high:g} Hz"),
            ("error_rms_total_m_s", "total"))):
        for col, sweep_map in enumerate(maps):
            axis = axes[row, col]
            grid = np.full((len(sweep_map.y_values), len(sweep_map.x_values)),
                           np.nan)
            measured = grid.copy()
            for r in rows:
                if r["map"] != sweep_map.name:
                    continue
                i = [_shown(v) for v in sweep_map.y_values].index(r["y"])
                j = [_shown(v) for v in sweep_map.x_values].index(r["x"])
                grid[i, j], measured[i, j] = r[key], r[f"measured.{key}"]
            image = axis.imshow(grid, cmap="RdBu", norm=norm, aspect="auto")
            for i in range(grid.shape[0]):
                for j in range(grid.shape[1]):
                    dark = abs(np.log(grid[i, j])) > 0.45
                    axis.text(j, i, f"{grid[i, j]:.2f}\n"
                              f"({measured[i, j]:.2f})", ha="center",
                              va="center", fontsize=8,
                              color="white" if dark else "black")
            axis.set_xticks(range(len(sweep_map.x_values)),
                            [str(_shown(v)) for v in sweep_map.x_values])
            axis.set_yticks(range(len(sweep_map.y_values)),
                            [str(_shown(v)) for v in sweep_map.y_values])
            axis.set_xlabel(sweep_map.x_name)
            axis.set_ylabel(sweep_map.y_name)
            axis.set_title(f"{sweep_map.name}: ratio {title}", fontsize=9)
    fig.colorbar(image, ax=axes, shrink=0.6,
                 label="without / with filter (> 1: the filter helps)")
    susp = station.suspension
    wheels = None if susp is None else susp.horizontal
    fig.suptitle(
        "Base filter's benefit, end effector's velocity error while the "
        "0.1 m/s step lasts: ground truth (measured as the paper)\n"
        f"around: loop lag {base.lag:.3g} s, damping ratio "
        f"{base.damping_ratio}, acceleration limit "
        f"{base.acceleration_limits[0]:g} m/s^2; suspension "
        + ("none" if susp is None else
           f"{susp.pitch_frequency:g} Hz, {susp.damping_ratio:g}")
        + ("" if wheels is None else
           f"; wheels {wheels.frequency:g} Hz, {wheels.damping_ratio:g}")
        + ("" if station.traction is None else
           f"; grip mu {station.traction.friction_coefficient:g}"),
        fontsize=9)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
