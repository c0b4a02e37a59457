"""The benchmark's results as JSON and as Markdown tables, and its goals.

`results` is the dict that drake_wbc.bench.commands.run_benchmarks
returns: every time in microseconds as timing.summarize statistics
(median, p10, p25, p75, p90, iqr, min, n).
"""


from drake_wbc.experiments.reports import json_text

GOALS = (
    ("solve_vs_daqp",
     "the distribution's solve at least 4x faster than DAQP's (both given "
     "the same J_wb and V_ee)", 4.0),
    ("with_kinematics_vs_drake_diffik",
     "with its kinematics, at least 12x faster than Drake's DiffIK with "
     "the same kinematics", 12.0),
    ("control_tick",
     "a full control tick under 0.5 ms", 500.0),
    ("scenario_real_time_factor",
     "every scenario at a real-time factor of at least 5", 5.0),
)
"""(key, statement, threshold) of each speed goal: a ratio (times
faster, median of the per-repetition ratios in wall-clock time), a time
in us (control_tick) or a real-time factor. The goals against another
commit (a tick at 0.4 of its, each scenario's closed loop 1.3x faster)
are measured by tools/bench_against.py."""

_SHOWN = {
    "solve_vs_daqp": "{:.2f}x (median ratio)",
    "with_kinematics_vs_drake_diffik": "{:.2f}x (median ratio)",
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
    race = results.get("distribution", {})
    for goal, part, peer in (
            ("solve_vs_daqp", "solve", "daqp"),
            ("with_kinematics_vs_drake_diffik", "with_kinematics",
             "drake_diffik")):
        entry = race.get(part, {}).get(peer)
        if entry is not None:
            measured[goal] = entry["ratio"]["median"]
    tick = results.get("control_tick")
    if tick:
        measured["control_tick"] = tick["tick"]["time_us"]["median"]
    scenarios = results.get("scenarios")
    if scenarios:
        factors = [entry["real_time_factor"] for entry in scenarios.values()
                   if "skipped" not in entry]
        if factors:
            measured["scenario_real_time_factor"] = min(factors)
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
    path.write_text(json_text(results))
    return path


def _time(entry):
    """Four table cells: wall-clock median, p10, p90; CPU median."""
    wall = entry["time_us"]
    return [f"{wall[k]:.1f}" for k in ("median", "p10", "p90")] + [
        f"{entry['cpu_us']['median']:.1f}"]


TIME_HEADER = ["median us", "p10 us", "p90 us", "CPU median us"]


def _ratio(entry):
    wall, cpu = entry["ratio"], entry["cpu_ratio"]
    return [f"{wall['median']:.2f} ({wall['p10']:.2f}-{wall['p90']:.2f})",
            f"{cpu['median']:.2f}"]


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
    robot = results.get("robot")
    if robot:
        lines += ["", f"Robot: {robot['name']} ({robot['arm_joints']} arm "
                  "joints)."]
    race = results.get("distribution")
    if race:
        lines += ["", "## Motion distribution (9-DoF, eqs. (wbsln)/(wbccm))",
                  "", f"{race['problems']} problems, a new q_a each. "
                  "Fairness, checked before timing: largest "
                  "|V_wb - V_wb(closed_form)| over the problems at most "
                  f"{race['tolerance']:g} for every same-problem contender"
                  f": {'all agree' if race['fair'] else 'DISAGREEMENT'}. "
                  "Ratios: the contender's time over closed_form's, median"
                  " (p10-p90) of the per-repetition ratios.", "",
                  "The kinematics (the floor of every contender with the "
                  "same kinematics) and the QP peers' data preparation "
                  "alone:", ""]
        lines += _table(["what", *TIME_HEADER], [
            ["kinematics (ArmKinematics.evaluate: J_a, p_ee, compiled)",
             *_time(race["kinematics"])],
            ["QP data preparation (J_wb, Q, V_n^0; unchecked)",
             *_time(race["qp_data"])]])
        for part, title in (
                ("solve", "The solve, every contender given the same "
                          "data (p_ee for the closed form; J_wb, Q and V_n^0"
                          " for the peers) and V_ee:"),
                ("with_kinematics", "With the kinematics, from q_a:")):
            lines += ["", title, ""]
            rows = []
            for name, entry in race[part].items():
                rows.append([
                    name, *_time(entry), *_ratio(entry),
                    f"{entry['max_abs_difference']:.1e}",
                    "yes" if entry["same_problem"] else "no (joint space)"])
            lines += _table(["contender", *TIME_HEADER,
                             "time / closed_form (p10-p90)",
                             "CPU / closed_form", "max difference",
                             "same problem"], rows)
    tick = results.get("control_tick")
    if tick:
        lines += ["", "## One control tick (controller alone, "
                  f"{tick['rate_hz']:g} Hz, {tick['obstacle_points']} "
                  "obstacle points, new measurements every tick from "
                  f"{tick['measurement_sets']} sets)", ""]
        rows = [["full tick (commands pulled)", *_time(tick["tick"]), "",
                 "", ""],
                ["full tick, commands not pulled",
                 *_time(tick["tick_unpulled"]), "", "", ""],
                ["framework floor (the same diagram, stages that do "
                 "nothing)", *_time(tick["framework_floor"]), "", "", ""]]
        for name, entry in tick["stages"].items():
            median = entry["tick"]["time_us"]["median"]
            hollow = entry["hollow"]["time_us"]["median"]
            rows.append([f"stage {name}", *_time(entry["tick"]),
                         f"{entry['inputs']['time_us']['median']:.1f}",
                         f"{hollow:.1f}", f"{median - hollow:.1f}"])
        lines += _table(["what", *TIME_HEADER,
                         "of which fixing inputs (median)",
                         "hollow twin (median)",
                         "own work (median, less the twin)"], rows)
        lines += ["", "A stage's hollow twin has its ports, feedthrough "
                  "and state and does no work (the framework floor's "
                  "stage, a Python system, ticked alone the same way): "
                  "the rest is the stage's own work, below zero where the "
                  "stage is built of Drake's C++ systems."]
    scaling = results.get("scaling")
    if scaling:
        lines += ["", "## How the cost grows", ""]
        rows = [[f"{e['points']} points", f"{e['rate_hz']:g} Hz",
                 *_time(dict(time_us=e["tick_us"], cpu_us=e["cpu_us"])),
                 f"{e['ticks_per_second']:.0f}",
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
            if "skipped" in entry:
                rows.append([name, "skipped: " + entry["skipped"], "", "",
                             "", ""])
                continue
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
