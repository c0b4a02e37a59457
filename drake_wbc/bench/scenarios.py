"""Real-time factor and peak memory of each scenario's closed loop.

Each run happens in a child process of its own (multiprocessing, spawn),
so that its peak resident memory (resource.getrusage, ru_maxrss) is that
of one run alone, from a fresh interpreter: Python, Drake, the station
(plant, LIDARs, scene) and the controller, the loggers of
drake_wbc.experiments.runner included. The run is the scenario's first variant,
built by runner.build_closed_loop and started as runner.simulate starts
it; it advances in chunks of `chunk` simulated seconds, and the real-time
factor of every chunk is kept, so that a run gives its spread as well as
its overall figure (simulated time over wall time, the build excluded).

On another robot (a description's file, `drake-wbc bench --robot`), each
scenario runs on that robot as `drake-wbc run SCENARIO --robot FILE`
runs it (drake_wbc.experiments.scenario.with_robot); a scenario that does
not apply to it (with_robot's ValueError, e.g. a static obstacle on
its footprint) is reported as skipped, with the reason, and not run.
"""

import multiprocessing
import resource
import time

import numpy as np

from drake_wbc.math.validation import positive, whole_number


def _run_in_child(path, duration, chunk, robot=None):
    """The body of the child process; returns a plain dict ({"skipped":
    reason} when the scenario does not apply to `robot`)."""
    started = time.perf_counter()

    from drake_wbc.controller.run_log import advance_times
    from drake_wbc.experiments.runner import build_closed_loop, start_simulator
    from drake_wbc.experiments.scenario import (
        load_scenario,
        scenario_robot,
        with_robot,
    )

    imported = time.perf_counter()
    scenario = load_scenario(path)
    if robot is not None:
        try:
            scenario = with_robot(scenario, robot, echo=None)
        except ValueError as error:
            return {"skipped": str(error)}
    duration = scenario.duration if duration is None else min(
        duration, scenario.duration)
    loop = build_closed_loop(scenario, scenario.variants[0])
    simulator = start_simulator(loop)
    built = time.perf_counter()
    factors, t = [], 0.0
    for step_end in advance_times(duration, chunk):
        wall = time.perf_counter()
        simulator.AdvanceTo(step_end)
        factors.append((step_end - t) / (time.perf_counter() - wall))
        t = step_end
    finished = time.perf_counter()
    return {
        "robot": scenario_robot(scenario).name,
        "variant": scenario.variants[0].name,
        "simulated_s": duration,
        "wall_s": finished - built,
        "real_time_factor": duration / (finished - built),
        "chunk_real_time_factors": factors,
        "import_s": imported - started,
        "build_s": built - imported,
        # Linux reports ru_maxrss in KiB.
        "peak_memory_mib": resource.getrusage(
            resource.RUSAGE_SELF).ru_maxrss / 1024.0,
    }


def run_scenario_in_child(path, duration=None, chunk=0.5, robot=None):
    """Runs one scenario in a fresh spawned process.

    Args:
        path: the scenario file.
        duration: simulated seconds (the scenario's own if None; never
            more than it).
        chunk: simulated seconds between two wall-clock readings.
        robot: a robot description's file to run the scenario on, or
            None for the scenario's own robot.

    Returns:
        dict: robot (its name), variant, simulated_s, wall_s,
        real_time_factor,
        chunk_real_time_factors, import_s, build_s, peak_memory_mib; or
        {"skipped": reason} if the scenario does not apply to `robot`.
    """
    if duration is not None:
        positive("duration", duration)
    positive("chunk", chunk)
    context = multiprocessing.get_context("spawn")
    with context.Pool(1, maxtasksperchild=1) as pool:
        return pool.apply(_run_in_child, (
            str(path), duration, chunk,
            None if robot is None else str(robot)))


def measure_scenarios(paths, duration=None, repeats=1, chunk=0.5,
                      echo=None, robot=None):
    """Runs every scenario `repeats` times, round-robin, one at a time,
    on `robot` (a description's file) if given.

    Returns:
        dict scenario name -> {"runs": [child results], "real_time_factor":
        median over runs, "chunk_real_time_factor": all chunks' factors
        (for the spread), "peak_memory_mib": largest over runs}, or
        {"skipped": reason} for a scenario that does not apply to
        `robot` (tried once).
    """
    repeats = whole_number("repeats", repeats, minimum=1)
    results = {path.stem: [] for path in paths}
    skipped = {}
    for r in range(repeats):
        for path in paths:
            if path.stem in skipped:
                continue
            run = run_scenario_in_child(path, duration, chunk, robot)
            if "skipped" in run:
                skipped[path.stem] = run["skipped"]
                if echo is not None:
                    echo(f"  {path.stem}: skipped, it does not apply to "
                         f"this robot ({run['skipped']})")
                continue
            results[path.stem].append(run)
            if echo is not None:
                echo(f"  {path.stem} (run {r + 1}/{repeats}): "
                     f"{run['simulated_s']:.1f} s simulated, real-time "
                     f"factor {run['real_time_factor']:.2f}, peak memory "
                     f"{run['peak_memory_mib']:.0f} MiB")
    summary = {}
    for name, runs in results.items():
        if name in skipped:
            summary[name] = {"skipped": skipped[name]}
            continue
        summary[name] = {
            "runs": runs,
            "real_time_factor": float(np.median(
                [run["real_time_factor"] for run in runs])),
            "chunk_real_time_factor": np.concatenate(
                [run["chunk_real_time_factors"] for run in runs]),
            "peak_memory_mib": max(run["peak_memory_mib"] for run in runs),
        }
    return summary
