"""Where the time goes: cProfile of control ticks and of a scenario run."""

import cProfile
import io
import pstats


def profile_text(function, top=30):
    """Runs `function()` under cProfile; returns the `top` functions by
    own time, then by cumulative time, as text."""
    profiler = cProfile.Profile()
    profiler.enable()
    function()
    profiler.disable()
    out = io.StringIO()
    for key in ("tottime", "cumulative"):
        out.write(f"=== sorted by {key} ===\n")
        stats = pstats.Stats(profiler, stream=out)
        stats.strip_dirs().sort_stats(key).print_stats(top)
    return out.getvalue()


def profile_ticks(ticker, count=300, top=30):
    """Profile of `count` ticks of a control_tick.ControllerTicker."""
    return profile_text(ticker.ticks(count), top)


def profile_scenario(path, duration=2.0, top=30, robot=None):
    """Profile of `duration` simulated seconds of a scenario's first
    variant (the closed loop of drake_wbc.experiments.runner), in this
    process, on the robot of the description file `robot` if given."""
    from drake_wbc.experiments.runner import build_closed_loop, simulate
    from drake_wbc.experiments.scenario import load_scenario, with_robot

    scenario = load_scenario(path)
    if robot is not None:
        scenario = with_robot(scenario, robot, echo=None)
    loop = build_closed_loop(scenario, scenario.variants[0])
    return profile_text(lambda: simulate(loop, duration=duration), top)
