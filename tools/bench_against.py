#!/usr/bin/env python3
"""Times the controller's tick and each scenario's closed loop here and at
another commit, interleaved in one run.

Starts one worker process per checkout (this one, and the other commit
checked out beside it as a detached git worktree). The rounds alternate
between the two (the order flips every round), so that a slow spell of
the machine hits both alike; every figure is kept in wall-clock time and
in the worker thread's CPU time (time.thread_time_ns, steadier when other
processes share the cores).

- The tick: each worker builds its checkout's controller in the ticker of
  THIS checkout's drake_wbc/bench/control_tick.py (loaded by path, so
  that both sides are measured by the same bench: measurements new every
  tick, AdvanceTo((k + 1) h), the station's commands pulled), and a round
  times a batch of ticks from the controller's initial state.
- The closed loop (--scenarios): in each round, for each scenario, each
  worker builds its checkout's closed loop of the scenario's first
  variant (drake_wbc.experiments.runner.build_closed_loop, untimed) and
  times `--seconds` simulated seconds of it from its initial state, in
  the chunks runner.simulate advances by.

It prints, for the tick and for each scenario, the median of each side
and the median of the per-round ratios here / other (below 1: faster
here) with the speed-up other / here; --json writes them too.

    python tools/bench_against.py --against 0df0251
    python tools/bench_against.py --against main --rounds 40 --ticks 300
    python tools/bench_against.py --against 0df0251 --scenarios all
    python tools/bench_against.py --against 0df0251 --no-tick \\
        --scenarios wiping line_tracking --seconds 5
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

TICKER = ROOT / "drake_wbc" / "bench" / "control_tick.py"
"""The bench's ticker, the same for both sides."""

WORKER = r"""
import importlib.util, json, sys, time

spec = importlib.util.spec_from_file_location("bench_ticker", sys.argv[1])
ticker_module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ticker_module)
ticks = int(sys.argv[2])
run_ticks = ticker_module.make_ticker().ticks(ticks) if ticks else None
if run_ticks is not None:
    run_ticks()  # warm up


def timed(work):
    wall, cpu = time.perf_counter_ns(), time.thread_time_ns()
    units = work()
    return [1e-9 * (time.perf_counter_ns() - wall) / units,
            1e-9 * (time.thread_time_ns() - cpu) / units]


def closed_loop(name, seconds):
    from pydrake.systems.analysis import Simulator

    from drake_wbc.experiments.runner import build_closed_loop
    from drake_wbc.experiments.scenario import find_scenario, load_scenario

    scenario = load_scenario(find_scenario(name))
    duration = min(seconds, scenario.duration)
    loop = build_closed_loop(scenario, scenario.variants[0])
    simulator = Simulator(loop.diagram)
    root = simulator.get_mutable_context()
    loop.station.set_initial_state(root)
    loop.controller.initialize(
        root, arm_position=scenario.station.initial_arm_positions)
    simulator.Initialize()
    chunk = max(duration / 200.0, scenario.controller.time_step)

    def run():
        t = 0.0
        while t < duration - 1e-12:
            t = min(t + chunk, duration)
            simulator.AdvanceTo(t)
        return duration

    return timed(run)  # per simulated second


def scenarios():
    from drake_wbc.experiments.scenario import scenario_files

    return [path.stem for path in scenario_files()]


print("ready", flush=True)
for line in sys.stdin:
    request = json.loads(line)
    try:
        if request["kind"] == "tick":
            answer = timed(run_ticks)
        elif request["kind"] == "scenarios":
            answer = scenarios()
        else:
            answer = closed_loop(request["name"], request["seconds"])
    except Exception as error:  # said by the parent, naming the checkout
        answer = {"error": f"{type(error).__name__}: {error}"}
    print(json.dumps(answer), flush=True)
"""


def start_worker(checkout, ticks):
    """A worker process in `checkout` (ticks a batch; 0: no ticker)."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    worker = subprocess.Popen(
        [sys.executable, "-c", WORKER, str(TICKER), str(ticks)],
        cwd=checkout, env=env, stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, text=True)
    worker.checkout = checkout
    if worker.stdout.readline().strip() != "ready":
        raise RuntimeError(f"the worker in {checkout} did not start")
    return worker


def ask(worker, request):
    """The worker's answer to `request`: [wall-clock s, thread CPU s] per
    unit (a tick, or a simulated second) of one timed request, or the
    names of its checkout's scenarios."""
    worker.stdin.write(json.dumps(request) + "\n")
    worker.stdin.flush()
    answer = json.loads(worker.stdout.readline())
    if isinstance(answer, dict):
        raise SystemExit(f"bench_against: the worker in {worker.checkout} "
                         f"failed on {request}: {answer['error']}")
    return answer


def scenario_names(requested, workers):
    """The scenarios named by --scenarios that both checkouts have
    (`all`: every scenario of both); a named one that either lacks is an
    error, the ones `all` leaves out are said."""
    known = {side: ask(worker, {"kind": "scenarios"})
             for side, worker in workers.items()}
    both = [name for name in known["here"]
            if all(name in names for names in known.values())]
    if requested == ["all"]:
        left_out = sorted(set().union(*known.values()) - set(both))
        if left_out:
            print(f"bench_against: not in both checkouts, left out: "
                  f"{', '.join(left_out)}")
        return both
    missing = [name for name in requested if name not in both]
    if missing:
        raise SystemExit(
            f"bench_against: --scenarios {' '.join(missing)}: not a "
            f"scenario of both checkouts; both have {', '.join(both)}")
    return requested


def summary(times, other):
    """Medians and per-round ratios of `times` (name -> list of
    [wall, cpu]), as a dict of plain floats."""
    result = {}
    for column, clock in enumerate(("wall", "cpu")):
        here = [v[column] for v in times["here"]]
        there = [v[column] for v in times[other]]
        ratios = [a / b for a, b in zip(here, there, strict=True)]
        result[clock] = dict(
            here=statistics.median(here), other=statistics.median(there),
            ratio=statistics.median(ratios), ratio_min=min(ratios),
            ratio_max=max(ratios), speed_up=1.0 / statistics.median(ratios))
    return result


def show(title, unit, scale, entry, other, rounds):
    print(f"{title} ({rounds} rounds):")
    for clock in ("wall", "cpu"):
        e = entry[clock]
        print(f"  {clock:>4}: here {e['here'] * scale:9.1f} {unit}, "
              f"{other} {e['other'] * scale:9.1f} {unit}; here / {other} "
              f"{e['ratio']:.3f} (rounds {e['ratio_min']:.3f} to "
              f"{e['ratio_max']:.3f}), speed-up {e['speed_up']:.2f}x")


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--against", required=True,
                        help="the other commit (any git revision)")
    parser.add_argument("--rounds", type=int, default=30,
                        help="interleaved rounds (default 30)")
    parser.add_argument("--ticks", type=int, default=200,
                        help="ticks a batch (default 200)")
    parser.add_argument("--no-tick", action="store_true",
                        help="do not time the tick")
    parser.add_argument("--scenarios", nargs="*", default=[],
                        help="scenarios whose closed loop to time (`all`: "
                             "every one)")
    parser.add_argument("--seconds", type=float, default=2.0,
                        help="simulated seconds of each closed loop a "
                             "round (default 2; never more than the "
                             "scenario's duration)")
    parser.add_argument("--json", type=Path, default=None,
                        help="also write the figures to this file")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.ticks < 1 or not args.seconds > 0:
        parser.error("--rounds and --ticks must be at least 1, --seconds "
                     "positive")
    if args.no_tick and not args.scenarios:
        parser.error("nothing to time: --no-tick without --scenarios")
    commit = subprocess.run(
        ["git", "rev-parse", "--short", args.against], cwd=ROOT,
        check=True, capture_output=True, text=True).stdout.strip()
    ticks = 0 if args.no_tick else args.ticks
    with tempfile.TemporaryDirectory() as scratch:
        other = Path(scratch) / f"at_{commit}"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet",
                        str(other), commit], cwd=ROOT, check=True)
        try:
            workers = {"here": start_worker(ROOT, ticks),
                       commit: start_worker(other, ticks)}
            parts = ([] if args.no_tick else [("tick", {"kind": "tick"})])
            parts += [(name, {"kind": "scenario", "name": name,
                              "seconds": args.seconds})
                      for name in scenario_names(args.scenarios, workers)]
            times = {part: {"here": [], commit: []} for part, _ in parts}
            for i in range(args.rounds):
                for j, (part, request) in enumerate(parts):
                    order = list(workers)
                    if (i + j) % 2:
                        order.reverse()
                    for side in order:
                        times[part][side].append(ask(workers[side],
                                                     request))
            for worker in workers.values():
                worker.stdin.close()
                worker.wait()
        finally:
            subprocess.run(["git", "worktree", "remove", "--force",
                            str(other)], cwd=ROOT, check=True)
    results = {part: summary(values, commit)
               for part, values in times.items()}
    for part, entry in results.items():
        if part == "tick":
            show(f"one control tick, {args.ticks} a batch", "us", 1e6,
                 entry, commit, args.rounds)
        else:
            show(f"closed loop {part}, {args.seconds:g} s simulated",
                 "ms per simulated s", 1e3, entry, commit, args.rounds)
    if args.json is not None:
        args.json.write_text(json.dumps(dict(
            against=commit, rounds=args.rounds, ticks=args.ticks,
            seconds=args.seconds, results=results), indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
