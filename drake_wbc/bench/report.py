"""The benchmark's results as JSON and as Markdown tables, and its goals.

`results` is the dict that drake_wbc.bench.commands.run_benchmarks
returns: every time in microseconds as timing.summarize statistics
(median, p10, p25, p75, p90, iqr, min, n).
"""

import json

from drake_wbc.experiments.reports import plain_values

GOALS = (
    ("closed_form_vs_drake_diffik",
     "closed-form distribution at least 3x faster than Drake's DiffIK", 3.0),
    ("closed_form_vs_qpsolvers",
     "closed-form distribution at least 20x faster than every qpsolvers "
     "formulation", 20.0),
    ("control_tick",
     "a full control tick under 0.5 ms", 500.0),
    ("scenario_real_time_factor",
     "every scenario at a real-time factor of at least 5", 5.0),
)
"""(key, statement, threshold) of each speed goal: a ratio (times
faster), a time in us (control_tick) or a real-time factor."""

_SHOWN = {
    "closed_form_vs_drake_diffik": "{:.2f}x (median ratio)",
    "closed_form_vs_qpsolvers": "{:.2f}x (the fastest solver's median ratio)",
    "control_tick": "{:.0f} us (median)",
    "scenario_real_time_factor": "{:.2f} (the slowest scenario)",
}
"""How the Markdown table shows each goal's measured value."""


def evaluate_goals(results):
    """Whether each goal of GOALS is met, from `results`.

    Returns:
        list of dicts: goal, statement, threshold, measured, met (None
        when the part was not measured).
    """
    measured = {}
    race = results.get("distribution", {}).get("contenders", {})
    if "drake_diffik" in race:
        measured["closed_form_vs_drake_diffik"] = \
            race["drake_diffik"]["ratio_to_closed_form"]["median"]
    qp = [entry["ratio_to_closed_form"]["median"]
          for name, entry in race.items() if name.startswith("qpsolvers_")]
    if qp:
        measured["closed_form_vs_qpsolvers"] = min(qp)
    tick = results.get("control_tick")
    if tick:
        measured["control_tick"] = tick["tick_us"]["median"]
    scenarios = results.get("scenarios")
    if scenarios:
        measured["scenario_real_time_factor"] = min(
            entry["real_time_factor"] for entry in scenarios.values())
    goals = []
    for key, statement, threshold in GOALS:
        value = measured.get(key)
        if value is None:
            met = None
        elif key == "control_tick":
            met = value < threshold
        else:
            met = value >= threshold
        goals.append(dict(goal=key, statement=statement,
                          threshold=threshold, measured=value, met=met))
    return goals


def write_json(results, path):
    """Writes `results` as JSON to `path`."""
    path.write_text(json.dumps(plain_values(results), indent=2))
    return path


def _time(stats):
    """Three table cells: median, p10, p90."""
    return [f"{stats[k]:.1f}" for k in ("median", "p10", "p90")]


TIME_HEADER = ["median us", "p10 us", "p90 us"]


def _table(header, rows):
    lines = ["| " + " | ".join(header) + " |",
             "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return lines


def markdown(results):
    """The results as Markdown: one table per part, then the goals."""
    env = results["environment"]
    packages = ", ".join(f"{k} {v}" for k, v in env["packages"].items()
                         if v is not None)
    settings = results["settings"]
    lines = [
        "# drake-wbc bench",
        "",
        f"Machine: {env['cpu_model']}, {env['cpu_count']} cores; Python "
        f"{env['python']}; {packages}.",
        f"Settings: {', '.join(f'{k} {v}' for k, v in settings.items())}."
        " Times in microseconds per solve or tick: median, p10 and p90 "
        "over the repetitions, contenders interleaved within each repetition.",
    ]
    race = results.get("distribution")
    if race:
        lines += ["", "## Motion distribution (9-DoF, eqs. (wbsln)/(wbccm))",
                  "", f"Fairness: largest |V_wb - V_wb(closed_form)| over "
                  f"the problems, tolerance {race['tolerance']:g}: "
                  f"{'all agree' if race['fair'] else 'DISAGREEMENT'}.", ""]
        rows = []
        for name, entry in race["contenders"].items():
            ratio = entry["ratio_to_closed_form"]
            rows.append([
                name, *_time(entry["time_us"]),
                f"{ratio['median']:.2f} ({ratio['p10']:.2f}-"
                f"{ratio['p90']:.2f})",
                f"{entry['max_abs_difference']:.1e}",
                "yes" if entry["same_problem"] else "no (joint space)"])
        lines += _table(["contender", *TIME_HEADER,
                         "time / closed_form (p10-p90)",
                         "max difference", "same problem"], rows)
    tick = results.get("control_tick")
    if tick:
        lines += ["", "## One control tick (controller alone, "
                  f"{tick['rate_hz']:g} Hz, {tick['obstacle_points']} "
                  "obstacle points)", ""]
        rows = [["full tick (measurements fixed again)",
                 *_time(tick["tick_us"]), ""],
                ["full tick (cached measurements)",
                 *_time(tick["tick_cached_us"]), ""],
                ["framework floor (the same diagram, stages that do "
                 "nothing)", *_time(tick["framework_floor_us"]), ""]]
        for name, entry in tick["stages"].items():
            rows.append([f"stage {name}", *_time(entry["tick_us"]),
                         f"{entry['inputs_us']['median']:.1f}"])
        lines += _table(["what", *TIME_HEADER,
                         "of which fixing inputs (median)"], rows)
    scaling = results.get("scaling")
    if scaling:
        lines += ["", "## How the cost grows", ""]
        rows = [[f"{e['points']} points", f"{e['rate_hz']:g} Hz",
                 *_time(e["tick_us"]), f"{e['ticks_per_second']:.0f}",
                 f"{e['load']:.2f}"]
                for e in scaling["obstacle_points"] + scaling["control_rate"]]
        lines += _table(["obstacle points", "control rate",
                         *TIME_HEADER,
                         "ticks per second", "load (tick / period)"], rows)
    scenarios = results.get("scenarios")
    if scenarios:
        lines += ["", "## Scenarios (closed loop: plant and controller, "
                  "each run in a child process)", ""]
        rows = []
        for name, entry in scenarios.items():
            chunks = entry["chunk_real_time_factor_stats"]
            run = entry["runs"][0]
            rows.append([name, f"{run['simulated_s']:.1f}",
                         f"{entry['real_time_factor']:.2f}",
                         f"{chunks['p10']:.2f}-{chunks['p90']:.2f}",
                         f"{run['build_s']:.2f}",
                         f"{entry['peak_memory_mib']:.0f}"])
        lines += _table(["scenario", "simulated s", "real-time factor",
                         "per-chunk p10-p90", "build s",
                         "peak memory MiB"], rows)
    lines += ["", "## Goals", ""]
    rows = []
    for goal in results["goals"]:
        value = goal["measured"]
        shown = ("not measured" if value is None
                 else _SHOWN[goal["goal"]].format(value))
        met = {None: "-", True: "met", False: "NOT met"}[goal["met"]]
        rows.append([goal["statement"], shown, met])
    lines += _table(["goal", "measured", ""], rows)
    return "\n".join(lines) + "\n"
