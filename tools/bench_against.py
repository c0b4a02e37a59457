#!/usr/bin/env python3
"""Times the controller's tick here and at another commit, interleaved.

Starts one worker process per checkout (this one, and the other commit
checked out beside it as a detached git worktree). Each builds the
controller of drake_wbc.bench.control_tick (the controller alone against
measurements that change every tick) and waits; the rounds then alternate
between the two, each timing a batch of ticks from the controller's
initial state, so that a slow spell of the machine hits both alike. It
prints the median tick of each and the median of the per-round ratios,
in wall-clock time and in the thread's CPU time (steadier when other
processes share the cores).

    python tools/bench_against.py --against c7eced0
    python tools/bench_against.py --against main --rounds 40 --ticks 300
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

WORKER = r"""
import json, sys, time
from drake_wbc.bench.control_tick import make_ticker
run = make_ticker().ticks(int(sys.argv[1]))
run()  # warm up
print("ready", flush=True)
for line in sys.stdin:
    wall, cpu = time.perf_counter(), time.thread_time()
    count = run()
    print(json.dumps([(time.perf_counter() - wall) / count,
                      (time.thread_time() - cpu) / count]), flush=True)
"""


def start_worker(checkout, ticks):
    """A worker process timing ticks in `checkout`."""
    env = dict(os.environ, PYTHONPATH=str(checkout))
    worker = subprocess.Popen(
        [sys.executable, "-c", WORKER, str(ticks)], cwd=checkout, env=env,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    if worker.stdout.readline().strip() != "ready":
        raise RuntimeError(f"the worker in {checkout} did not start")
    return worker


def time_batch(worker):
    """One batch's mean tick in s: [wall-clock time, the thread's CPU
    time]."""
    worker.stdin.write("go\n")
    worker.stdin.flush()
    return json.loads(worker.stdout.readline())


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--against", required=True,
                        help="the other commit (any git revision)")
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--ticks", type=int, default=200,
                        help="ticks a batch (default 200)")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.ticks < 1:
        parser.error("--rounds and --ticks must be at least 1")
    commit = subprocess.run(
        ["git", "rev-parse", "--short", args.against], cwd=ROOT,
        check=True, capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as scratch:
        other = Path(scratch) / f"at_{commit}"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet",
                        str(other), commit], cwd=ROOT, check=True)
        try:
            workers = {"here": start_worker(ROOT, args.ticks),
                       commit: start_worker(other, args.ticks)}
            times = {name: [] for name in workers}
            for i in range(args.rounds):
                order = list(workers) if i % 2 == 0 else list(workers)[::-1]
                for name in order:
                    times[name].append(time_batch(workers[name]))
            for worker in workers.values():
                worker.stdin.close()
                worker.wait()
        finally:
            subprocess.run(["git", "worktree", "remove", "--force",
                            str(other)], cwd=ROOT, check=True)
    for column, clock in enumerate(("wall-clock", "CPU")):
        print(f"{clock} time:")
        for name, values in times.items():
            values = [v[column] for v in values]
            print(f"  {name:>10}: median tick "
                  f"{statistics.median(values) * 1e6:7.1f} us (min "
                  f"{min(values) * 1e6:.1f}, max {max(values) * 1e6:.1f};"
                  f" {args.rounds} batches of {args.ticks})")
        ratios = [a[column] / b[column] for a, b in
                  zip(times["here"], times[commit], strict=True)]
        print(f"  here / {commit}: median ratio "
              f"{statistics.median(ratios):.3f} (per-round ratios "
              f"{min(ratios):.3f} to {max(ratios):.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
