"""`drake-wbc stress`: a seeded, randomised stress run of the closed loop.

N short closed-loop simulations (the controller of drake_wbc.controller
against the simulated station), each built from a random scenario
(drake_wbc.stress_cases.random_scenario): static obstacles, walking
people, a hand on the tool, a reference velocity, the loco-manipulation
or the intuitive pHRI mode. Case i of seed S is drawn from
numpy.random.default_rng([S, i]) only, so its result is the same run
serially, in worker processes or on a Dask cluster.

The invariants checked on every case (drake_wbc.stress_cases.violations):

1. the simulation runs to its end (no exception from Drake or the
   controller);
2. every logged signal is finite: the commands, the controller's
   diagnostics and the station's state (no NaN, no infinity);
3. every base velocity command lies within the base's velocity limits
   (station.base.velocity_limits: 1 m/s in x and y, 1 rad/s in yaw);
4. every joint position command moves each joint no faster than its
   velocity limit (1.57 rad/s on the Elfin5): the change between two
   consecutive commands over the control period;
5. every joint position command lies within the joint's limits;
6. the base's footprint never touches a static obstacle (distance from
   ground truth > 0);
7. every number of the case's record is finite.

Recorded but not an invariant: the least C_m, the least margin of the
measured joint positions to their limits, the closest approach of a
person (people walk where they like).

`run_stress(args)` prints a progress line (cases done / total, failures so
far) and a summary table, writes `stress.json` and `stress.csv` to the
output folder and returns 0 when every invariant held, 1 otherwise.
"""

import csv
import json
import math
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from drake_wbc.stress_cases import TIMING_KEYS, run_case, violations
from drake_wbc.validation import positive, whole_number

DEFAULT_DURATION = 4.0
"""Simulated time of each case, s."""

COLUMNS = (
    ("case", "case", "{:d}"),
    ("mode", "mode", "{}"),
    ("obstacles", "obst", "{:d}"),
    ("people", "ppl", "{:d}"),
    ("min_static_obstacle_distance_m", "d_obs m", "{:.3f}"),
    ("min_capability", "min C_m", "{:.4f}"),
    ("min_command_joint_limit_margin_rad", "q margin", "{:.3f}"),
    ("max_base_speed_command_m_s", "|v_b| m/s", "{:.3f}"),
    ("max_joint_speed_command_rad_s", "qdot rad/s", "{:.3f}"),
    ("all_finite", "finite", "{}"),
)
"""The summary table's columns: record key, heading, format."""


def add_stress_arguments(parser):
    """Adds the arguments of `drake-wbc stress` to `parser`."""
    parser.add_argument("--cases", type=int, default=20,
                        help="how many cases (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0,
                        help="the run's seed (default: %(default)s)")
    parser.add_argument(
        "--workers", type=int, default=None,
        help="worker processes (default: one per core); 1 runs the cases "
             "in this process")
    parser.add_argument(
        "--scheduler", default=None, metavar="ADDRESS",
        help="run the cases on the Dask distributed cluster of this "
             "scheduler (e.g. tcp://10.0.0.5:8786) instead of local "
             "processes")
    parser.add_argument(
        "--duration", type=float, default=DEFAULT_DURATION,
        help="simulated time of each case in s (default: %(default)s)")
    parser.add_argument(
        "--output", type=Path, default=Path("out") / "stress",
        help="folder for stress.json and stress.csv "
             "(default: %(default)s)")


class ProgressLine:
    """`stress: k / N cases done, f failed` on one line of `stream` (a new
    line per case when `stream` is not a terminal)."""

    def __init__(self, total, stream=None):
        self.total, self.done, self.failed = total, 0, 0
        self.stream = stream or sys.stderr

    def update(self, record):
        self.done += 1
        self.failed += bool(violations(record))
        text = (f"stress: {self.done} / {self.total} cases done, "
                f"{self.failed} failed")
        if self.stream.isatty():
            end = "\n" if self.done == self.total else ""
            self.stream.write("\r" + text + end)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


def run_cases(seed, cases, duration=DEFAULT_DURATION, workers=1,
              scheduler=None, on_done=None):
    """Runs cases 0 .. cases - 1 of `seed`; returns their records, in case
    order.

    Args:
        seed: a whole number >= 0.
        cases: how many cases, >= 1.
        duration: simulated time of each case, s.
        workers: worker processes (spawned); 1 runs the cases here, None
            one per core. Ignored with `scheduler`.
        scheduler: the address of a Dask distributed scheduler, a
            dask.distributed.Client, or None.
        on_done: called with each record as it comes in (any order).

    Raises:
        ValueError: naming a bad argument.
    """
    seed = whole_number("seed", seed)
    cases = whole_number("cases", cases, 1)
    duration = positive("duration", duration)
    on_done = on_done or (lambda record: None)
    if scheduler is not None:
        records = _on_dask(scheduler, seed, cases, duration, on_done)
    else:
        if workers is None:
            workers = os.cpu_count() or 1
        workers = whole_number("workers", workers, 1)
        records = _in_processes(seed, cases, duration, min(workers, cases),
                                on_done)
    return sorted(records, key=lambda record: record["case"])


def _in_processes(seed, cases, duration, workers, on_done):
    records = []
    if workers == 1:
        for index in range(cases):
            records.append(run_case(seed, index, duration))
            on_done(records[-1])
        return records
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers,
                             mp_context=context) as pool:
        futures = [pool.submit(run_case, seed, index, duration)
                   for index in range(cases)]
        for future in as_completed(futures):
            records.append(future.result())
            on_done(records[-1])
    return records


def _on_dask(scheduler, seed, cases, duration, on_done):
    from dask.distributed import Client
    from dask.distributed import as_completed as dask_completed

    client = scheduler if isinstance(scheduler, Client) else Client(
        scheduler)
    try:
        futures = [client.submit(run_case, seed, index, duration,
                                 pure=False, key=f"stress-{seed}-{index}")
                   for index in range(cases)]
        records = []
        for future in dask_completed(futures):
            records.append(future.result())
            on_done(records[-1])
        return records
    finally:
        if client is not scheduler:
            client.close()


def exit_code(records):
    """0 when no record breaks an invariant, else 1."""
    return 1 if any(violations(record) for record in records) else 0


def comparable(record):
    """`record` without the keys that depend on the machine (timing)."""
    return {k: v for k, v in record.items() if k not in TIMING_KEYS}


def summary_table(records):
    """The summary table of `records` as text, one line a case."""
    rows = [[heading for _, heading, _ in COLUMNS] + ["invariants"]]
    for record in records:
        broken = violations(record)
        row = []
        for key, _, form in COLUMNS:
            value = record.get(key)
            row.append("-" if value is None else form.format(value))
        row.append("; ".join(broken) if broken else "ok")
        rows.append(row)
    widths = [max(len(row[i]) for row in rows) for i in range(len(COLUMNS))]
    lines = ["  ".join(cell.rjust(width) for cell, width
                       in zip(row[:-1], widths, strict=True)) + "  " + row[-1]
             for row in rows]
    return "\n".join(lines)


def _json_ready(value):
    """`value` with non-finite floats as the strings "nan", "inf", "-inf"
    (strict JSON has no such numbers)."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_ready(v) for v in value]
    return value


def write_results(folder, settings, records):
    """Writes stress.json (the settings, each record with its broken
    invariants) and stress.csv (one row a case); returns both paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rows = [dict(record, violations=violations(record))
            for record in records]
    document = dict(settings, failed=sum(bool(r["violations"]) for r in rows),
                    cases=rows)
    json_path = folder / "stress.json"
    json_path.write_text(json.dumps(_json_ready(document), indent=1),
                         encoding="utf-8")
    keys = list(dict.fromkeys(k for record in records for k in record))
    csv_path = folder / "stress.csv"
    with csv_path.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=keys + ["violations"])
        writer.writeheader()
        for row in rows:
            writer.writerow(dict(row, violations="; ".join(
                row["violations"])))
    return json_path, csv_path


def run_stress(args):
    """Runs `drake-wbc stress` with the parsed `args`; returns the exit
    code (0: every invariant held; 1: one broke)."""
    workers = args.workers
    where = (f"on the Dask cluster at {args.scheduler}" if args.scheduler
             else f"in {workers or os.cpu_count() or 1} worker process(es)")
    print(f"drake-wbc stress: {args.cases} cases of {args.duration} s, seed "
          f"{args.seed}, {where}; writing to {args.output}/")
    progress = ProgressLine(args.cases)
    records = run_cases(args.seed, args.cases, args.duration, workers,
                        args.scheduler, on_done=progress.update)
    print(summary_table(records))
    settings = dict(seed=args.seed, duration_s=args.duration,
                    scheduler=args.scheduler, workers=workers)
    json_path, csv_path = write_results(args.output, settings, records)
    code = exit_code(records)
    failed = sum(bool(violations(r)) for r in records)
    print(f"{failed} of {len(records)} cases broke an invariant; wrote "
          f"{json_path} and {csv_path}")
    return code
