"""`drake-wbc stress`: a seeded, randomised stress run of the closed loop.

N short closed-loop simulations (the controller of drake_wbc.controller.diagram
against the simulated station), each built from a random scenario
(drake_wbc.stress.cases.random_scenario): static obstacles, walking
people, a hand on the tool, a reference velocity, the loco-manipulation
or the intuitive pHRI mode. Case i of seed S is drawn from
numpy.random.default_rng([S, i]) only, so its result is the same run
serially, in worker processes or on a Dask cluster.

The invariants checked on every case (drake_wbc.stress.cases.violations):

1. the simulation runs to its end (no exception from Drake or the
   controller);
2. every logged signal is finite: the commands, the controller's
   diagnostics and the station's state (no NaN, no infinity);
3. every base velocity command lies within the base's own velocity
   limits (the robot description's base.velocity_limits);
4. every joint position command moves each joint no faster than its
   velocity limit (the arm's own, from the robot's model and
   description): the change between two
   consecutive commands over the control period;
5. every joint position command lies within the joint's limits;
6. the base's footprint never touches a static obstacle (distance from
   ground truth > 0);
7. every number of the case's record is finite;
8. the base filter's output V_b^flt stays within the base's velocity
   limits (no wind-up: the controller's StopGate keeps the filter's input
   within them, and a filter with zeta >= 1 does not overshoot);
9. the simulated arm never faults: no position command breaks the
   arm's own position, speed or acceleration limits as its servo
   samples them (drake_wbc.station.arm_supervisor).

Recorded but not an invariant: the least C_m, the least margin of the
measured joint positions to their limits, the closest approach of a
person (people walk where they like). A margin or distance with nothing
to measure to (an arm of continuous joints alone, no obstacle) is
recorded as None, "-" in the table.

`run_stress(args)` checks its arguments before it touches anything,
prints a progress line (cases done / total, failures so far; a failing
case's broken invariants at once), appends each record to `stress.jsonl`
in the output folder as it completes (so a long run that is stopped
keeps what it did, and `--resume` runs only the cases missing from it),
then prints a summary (every case for a short run; for a long one the
spread of each column and the failing cases), writes `stress.json` and
`stress.csv` and returns 0 when every invariant held, 1 otherwise. Each
failing case's scenario is written beside them, `case_<K>.yaml` (`drake-wbc
run` runs it, with its logs and figures), and the summary gives the
command that runs that case alone: `drake-wbc stress --seed S --case K`
(with the run's duration, robot and output), which writes into
`<output>/case_<K>/`.

Stopping a run: the first Ctrl-C (SIGINT) or SIGTERM cancels the cases
under way (their worker processes are ended; the workers themselves
ignore Ctrl-C, which a terminal sends to them too), keeps every finished
case in the journal and returns 130 (128 + SIGINT) or 143 (128 +
SIGTERM), with one line saying what was kept, no traceback. A second
signal while it stops kills the workers and exits at once. A worker
whose parent is gone (killed with SIGKILL) ends itself within a second.
"""

import contextlib
import csv
import json
import multiprocessing
import os
import shlex
import signal
import sys
import threading
import time
from multiprocessing import resource_tracker
from pathlib import Path

from drake_wbc.experiments.reports import from_json_text, json_text
from drake_wbc.experiments.runner import wall_time_text
from drake_wbc.experiments.scenario import robot_option_file, scenario_text
from drake_wbc.math.validation import positive_duration, whole_number
from drake_wbc.robot.description import load_robot_description
from drake_wbc.stress.cases import (
    TIMING_KEYS,
    random_scenario,
    run_case,
    violations,
)
from drake_wbc.stress.stopping import Stopped, stop_within

DEFAULT_DURATION = 4.0
"""Simulated time of each case, s."""

MAX_CASES = 100_000
"""The most cases one run takes (at a few seconds a case, a day's work
for a few dozen cores); `--cases 1e12` listed them all before it ran
one."""

WORKERS_PER_CORE = 4
"""The most local worker processes a run starts, per core."""

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
        "--case", type=int, default=None, metavar="K",
        help="run case K of the seed alone (--cases is then ignored), "
             "writing into <output>/case_K/; a failing case's line of the "
             "summary gives this command")
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
        help="folder for stress.jsonl, stress.json and stress.csv "
             "(default: %(default)s)")
    parser.add_argument(
        "--resume", action="store_true",
        help="keep the records of an earlier run of the same seed, "
             "duration and robot found in the output folder's stress.jsonl "
             "and run only the missing cases")
    parser.add_argument(
        "--robot", type=Path, default=None,
        help="run the cases on the robot of this description YAML "
             "(default: the shipped one): the arm starts near its home, "
             "every limit is its own")


class ProgressLine:
    """`stress: k / N cases done, f failed, about t left` on one line of
    `stream` (a new line per case when `stream` is not a terminal)."""

    def __init__(self, total, stream=None):
        self.total, self.done, self.failed = total, 0, 0
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()

    def update(self, record):
        self.done += 1
        broken = violations(record)
        self.failed += bool(broken)
        elapsed = time.perf_counter() - self.start
        if self.done >= self.total:
            left = f"took {wall_time_text(elapsed)}"
        else:
            rest = elapsed / self.done * (self.total - self.done)
            left = f"about {wall_time_text(rest)} left"
        text = (f"stress: {self.done} / {self.total} cases done, "
                f"{self.failed} failed, {left}")
        if broken:
            text = (f"stress: case {record['case']} broke "
                    f"{'; '.join(broken)}\n{text}")
        if self.stream.isatty():
            end = "\n" if self.done == self.total else ""
            self.stream.write("\r" + text + end)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


def run_cases(seed, cases, duration=DEFAULT_DURATION, workers=1,
              scheduler=None, on_done=None, done=(), robot="", first=0):
    """Runs cases first .. cases - 1 of `seed`; returns their records, in
    case order.

    Args:
        seed: a whole number >= 0.
        cases: how many cases, >= 1 (the cases before `first` not run).
        duration: simulated time of each case, s.
        workers: worker processes (spawned); 1 runs the cases here, None
            one per core. Ignored with `scheduler`.
        scheduler: the address of a Dask distributed scheduler, a
            dask.distributed.Client, or None.
        on_done: called with each record as it comes in (any order).
        done: records of cases already run (e.g. `Journal.records`): they
            are returned as they are, and only the other cases run.
        robot: the robot's description file ("" for the shipped robot).
        first: the first case to run, a whole number < cases.

    Raises:
        ValueError: naming a bad argument.
    """
    seed, cases, duration, workers = check_arguments(seed, cases, duration,
                                                     workers)
    first = whole_number("first", first, 0, cases - 1)
    on_done = on_done or (lambda record: None)
    kept = {record["case"]: record for record in done
            if first <= record["case"] < cases}
    pending = [index for index in range(first, cases) if index not in kept]
    if not pending:
        records = []
    elif scheduler is not None:
        records = _on_dask(scheduler, seed, pending, duration, on_done,
                           robot)
    else:
        records = _in_processes(seed, pending, duration,
                                min(workers, len(pending)), on_done, robot)
    return sorted([*kept.values(), *records],
                  key=lambda record: record["case"])


def check_arguments(seed, cases, duration, workers, prefix=""):
    """(seed, cases, duration, workers) checked: whole numbers seed >= 0,
    cases >= 1 and workers >= 1 (None: one per core), duration > 0 s.

    `prefix` comes before each argument's name in an error ("--" names
    the command line's options).

    Raises:
        ValueError: naming the first bad argument, its value and what is
            allowed.
    """
    seed = whole_number(f"{prefix}seed", seed)
    cases = whole_number(f"{prefix}cases", cases, 1)
    if cases > MAX_CASES:
        raise ValueError(
            f"{prefix}cases = {cases} is not allowed: must be at most "
            f"{MAX_CASES} (a case takes seconds; run more as several runs "
            "of other seeds)")
    duration = positive_duration(f"{prefix}duration", duration)
    cores = os.cpu_count() or 1
    if workers is None:
        workers = cores
    workers = whole_number(f"{prefix}workers", workers, 1)
    if workers > WORKERS_PER_CORE * cores:
        raise ValueError(
            f"{prefix}workers = {workers} is not allowed: must be at most "
            f"{WORKERS_PER_CORE * cores} ({WORKERS_PER_CORE} a core, of "
            f"this machine's {cores}; each worker process loads Drake "
            "and runs a case at full speed)")
    return seed, cases, duration, workers


def checked_scheduler(address):
    """`address`, a command line's --scheduler, checked as the address of
    a Dask scheduler (a tcp or tls one needs its port), before anything
    is written; None stays None.

    Raises:
        ValueError: naming --scheduler, its value and what is allowed.
    """
    if address is None:
        return None
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme in ("tcp", "tls"):
            parse_host_port(location)
    except ValueError as error:
        raise ValueError(
            f"--scheduler = {address!r} is not allowed: {error} (must be a "
            "Dask scheduler's address, e.g. tcp://10.0.0.5:8786)") from None
    return address


def _in_processes(seed, indices, duration, workers, on_done, robot):
    records = []
    if workers == 1:
        for index in indices:
            records.append(run_case(seed, index, duration, robot))
            on_done(records[-1])
        return records
    context = multiprocessing.get_context("spawn")
    # A stop while the pool starts its workers would leave them half
    # started, so it waits until the pool exists; and the workers are
    # born with SIGINT blocked (a terminal's Ctrl-C reaches them too, and
    # would interrupt their start-up with a traceback).
    # Leaving the outer block, by the end or by an exception (Stopped),
    # terminates the workers: a stopped run does not wait for its cases.
    # The pool is in it before a stop held during its start is raised.
    with contextlib.ExitStack() as running:
        with signals_held(), _ctrl_c_blocked_at_birth():
            pool = running.enter_context(context.Pool(
                workers, initializer=_start_worker, initargs=(os.getpid(),)))
        jobs = [(seed, index, duration, robot) for index in indices]
        for record in pool.imap_unordered(_run_job, jobs):
            records.append(record)
            on_done(record)
    return records


@contextlib.contextmanager
def _ctrl_c_blocked_at_birth():
    """Within the block, SIGINT is blocked in this thread, and processes
    started here inherit the mask: a Ctrl-C does not interrupt their
    start-up, and _start_worker then ignores it. A SIGINT to this
    process meanwhile is not lost: another thread takes it, and this
    one's handler runs on leaving. Only on POSIX (elsewhere it does
    nothing)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    # Started first: starting the tracker unblocks SIGINT in this thread.
    resource_tracker.ensure_running()
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _run_job(job):
    """run_case(*job), in a worker process."""
    return run_case(*job)


def _start_worker(parent):
    """Prepares a worker process: Ctrl-C is the parent's to answer (a
    terminal sends it to the workers too), SIGTERM ends the worker, and a
    thread ends it when its parent is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a pending one is dropped
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    threading.Thread(target=_watch_parent, args=(parent,),
                     daemon=True).start()


def _watch_parent(parent, period=0.5):
    while os.getppid() == parent:
        time.sleep(period)
    os._exit(1)


_SIGNALS = {"held": 0, "pending": None, "received": []}
"""The state of stopped_by_signals: how deep in signals_held blocks, the
signal that came while held, the signals received."""


@contextlib.contextmanager
def stopped_by_signals():
    """Within the block, the first SIGINT or SIGTERM raises Stopped in the
    main thread (at the end of a `signals_held` block, if it came inside
    one); a second one, then or after the block (the process is
    stopping), kills the worker processes and exits the process at once
    (os._exit, 128 + its number). Outside the main thread (where no
    signal handler can be set) it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received = []
    _SIGNALS.update(held=0, pending=None, received=received)

    def handler(signum, frame):
        if received:
            _exit_now(128 + signum)
        received.append(signum)
        if _SIGNALS["held"]:
            _SIGNALS["pending"] = signum
            return
        raise Stopped(signum)

    previous = {number: signal.signal(number, handler)
                for number in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        if not received:  # once stopped, a signal exits at once to the end
            for number, action in previous.items():
                signal.signal(number, action)


@contextlib.contextmanager
def signals_held():
    """Within stopped_by_signals, a stop that comes inside this block is
    raised at its end (the block is not cut in the middle)."""
    _SIGNALS["held"] += 1
    try:
        yield
    finally:
        _SIGNALS["held"] -= 1
    pending = _SIGNALS["pending"]
    if pending is not None and not _SIGNALS["held"]:
        _SIGNALS["pending"] = None
        raise Stopped(pending)


def _exit_now(code):
    for child in multiprocessing.active_children():
        child.kill()
    os.write(2, b"\nstress: stopped at once\n")
    os._exit(code)


def _on_dask(scheduler, seed, indices, duration, on_done, robot):
    from dask.distributed import Client
    from dask.distributed import as_completed as dask_completed

    client = scheduler if isinstance(scheduler, Client) else Client(
        scheduler)
    try:
        futures = [client.submit(run_case, seed, index, duration, robot,
                                 pure=False, key=f"stress-{seed}-{index}")
                   for index in indices]
        records = []
        try:
            for future in dask_completed(futures):
                records.append(future.result())
                on_done(records[-1])
        except Stopped:
            client.cancel(futures)
            raise
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


class Journal:
    """`stress.jsonl`: the run's settings on the first line, then one
    record a line, appended and flushed as each case completes.

    Args:
        folder: the output folder (created if missing).
        settings: a dict of the run's settings (seed, duration_s, ...).
        resume: keep the records of a journal already in `folder` whose
            seed and duration match `settings` (`records`); otherwise the
            journal starts afresh.
        report: called with a line of text for each line of the old
            journal that is not a record (skipped); by default printed
            on stderr.

    The journal is rewritten (settings and kept records) into a new file
    that then replaces the old one, so that a run stopped at any moment
    leaves a whole journal behind.
    """

    def __init__(self, folder, settings, resume=False, report=None):
        self.path = Path(folder) / "stress.jsonl"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._report = report or (lambda text: print(text, file=sys.stderr))
        self.records = self._earlier(settings) if resume else []
        fresh = self.path.with_name(self.path.name + ".new")
        with fresh.open("w", encoding="utf-8") as stream:
            stream.write(json_text({"settings": settings}, None) + "\n")
            for record in self.records:
                stream.write(json_text(record, None) + "\n")
        os.replace(fresh, self.path)

    def _earlier(self, settings):
        if not self.path.exists():
            return []
        text = self.path.read_bytes().decode("utf-8", errors="replace")
        lines = text.splitlines()
        if not lines:
            return []
        try:
            earlier = json.loads(lines[0])["settings"]
            earlier = {key: earlier[key] for key in ("seed", "duration_s")}
        except (ValueError, TypeError, KeyError):
            raise ValueError(
                f"--resume is not allowed with {self.path}: its first line, "
                f"{_clipped(lines[0])}, is not the settings of a run "
                "(choose another --output, or run without --resume)"
            ) from None
        if any(earlier[key] != settings[key] for key in earlier):
            raise ValueError(
                f"--resume is not allowed with seed {settings['seed']} and "
                f"duration {settings['duration_s']} s: {self.path} holds a "
                f"run of seed {earlier['seed']} and duration "
                f"{earlier['duration_s']} s (choose another --output)")
        records = {}
        for number, line in enumerate(lines[1:], start=2):
            record = _record_from_line(line)
            if record is None:
                self._report(
                    f"stress: {self.path} line {number} is not a record "
                    f"({_clipped(line)}); skipped, its case runs again")
                continue
            records[record["case"]] = record
        return [records[index] for index in sorted(records)]

    def append(self, record):
        """Appends `record` as one line, flushed to disk at once."""
        with self.path.open("a", encoding="utf-8") as stream:
            stream.write(json_text(record, None) + "\n")


def _record_from_line(line):
    """The record of one journal line, or None when the line is not one
    (cut short by a stopped run, or damaged): a JSON object with a whole
    case number >= 0."""
    try:
        record = from_json_text(line)
    except ValueError:
        return None
    if not isinstance(record, dict):
        return None
    case = record.get("case")
    if isinstance(case, bool) or not isinstance(case, int) or case < 0:
        return None
    return record


def _clipped(line, limit=60):
    line = line.strip()
    return repr(line if len(line) <= limit else line[:limit] + "...")


SUMMARY_ROWS = 30
"""Runs of more cases than this print the spread of each column and the
failing cases, not every case."""


def summary_table(records):
    """The summary of `records` as text: one line a case, or, for more
    than SUMMARY_ROWS cases, the least, median and largest value of each
    column followed by the failing cases."""
    if len(records) > SUMMARY_ROWS:
        return _spread(records)
    return _rows(records)


def _spread(records):
    lines = [f"{'':>12}  {'least':>10}  {'median':>10}  {'largest':>10}"]
    for key, heading, form in COLUMNS[4:-1]:
        values = [record[key] for record in records
                  if isinstance(record.get(key), (int, float))]
        if not values:
            continue
        least, median, largest = (min(values), sorted(values)[
            len(values) // 2], max(values))
        lines.append(f"{heading:>12}  " + "  ".join(
            form.format(v).rjust(10) for v in (least, median, largest)))
    failing = [record for record in records if violations(record)]
    lines.append(f"{len(failing)} failing case(s)" + (
        ":" if failing else ""))
    if failing:
        lines.append(_rows(failing))
    return "\n".join(lines)


def _rows(records):
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
    json_path.write_text(json_text(document, 1), encoding="utf-8")
    keys = list(dict.fromkeys(k for record in records for k in record))
    csv_path = folder / "stress.csv"
    with csv_path.open("w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=keys + ["violations"])
        writer.writeheader()
        for row in rows:
            writer.writerow(dict(row, violations="; ".join(
                row["violations"])))
    return json_path, csv_path


def rerun_command(settings, case, output):
    """The command line that runs case `case` of the run of `settings`
    alone, writing into `output`/case_<case>/."""
    words = ["drake-wbc", "stress", "--seed", str(settings["seed"]),
             "--case", str(case), "--duration", str(settings["duration_s"])]
    if settings["robot"]:
        words += ["--robot", settings["robot"]]
    return shlex.join(words + ["--output", str(output)])


def rerun_lines(folder, output, settings, records):
    """For each failing case of `records`: writes its scenario into
    `folder` (beside stress.json), `case_<K>.yaml`, where it can be drawn
    (scenario_text), and returns a line saying how to run it again
    (`rerun_command`, `output` the run's --output) and where its
    scenario is."""
    lines = []
    for record in records:
        if not violations(record):
            continue
        case = record["case"]
        line = (f"case {case}: run it alone with "
                f"{rerun_command(settings, case, output)}")
        try:
            scenario = random_scenario(settings["seed"], case,
                                       settings["duration_s"],
                                       settings["robot"])
        except Exception as error:  # the case's own error, recorded
            lines.append(f"{line} (its scenario cannot be drawn: "
                         f"{type(error).__name__}: {error})")
            continue
        path = Path(folder) / f"case_{case}.yaml"
        path.write_text(scenario_text(scenario), encoding="utf-8")
        lines.append(f"{line}; its scenario, for drake-wbc run: {path}")
    return lines


def run_stress(args):
    """Runs `drake-wbc stress` with the parsed `args`; returns the exit
    code (0: every invariant held; 1: one broke; 130 or 143: stopped by
    SIGINT or SIGTERM, the finished cases kept in the journal).

    Raises:
        ValueError: naming a bad argument, before anything is written.
    """
    first, cases, output = 0, args.cases, args.output
    if args.case is not None:
        first = whole_number("--case", args.case, 0, MAX_CASES - 1)
        cases, output = first + 1, args.output / f"case_{first}"
    seed, cases, duration, workers = check_arguments(
        args.seed, cases, args.duration, args.workers, prefix="--")
    checked_scheduler(args.scheduler)
    where = (f"on the Dask cluster at {args.scheduler}" if args.scheduler
             else "in this process" if workers == 1
             else f"in {workers} worker processes")
    robot = "" if args.robot is None else str(
        robot_option_file(args.robot).resolve())
    if robot:
        load_robot_description(robot)  # checked before the journal
    settings = dict(seed=seed, duration_s=duration,
                    scheduler=args.scheduler, workers=args.workers,
                    robot=robot)
    journal = None
    with stopped_by_signals():
        try:
            journal = Journal(output, settings, resume=args.resume)
            what = (f"{cases} cases" if args.case is None
                    else f"case {first}")
            print(f"drake-wbc stress: {what} of {duration} s, seed "
                  f"{seed}, {where}; writing to {output}/")
            kept = [r for r in journal.records if first <= r["case"] < cases]
            if kept:
                print(f"resuming: {len(kept)} case(s) kept from "
                      f"{journal.path}")
            progress = ProgressLine(cases - first - len(kept))

            def on_done(record):
                journal.append(record)
                progress.update(record)

            records = run_cases(seed, cases, duration, workers,
                                args.scheduler, on_done=on_done, done=kept,
                                robot=robot, first=first)
            print(summary_table(records))
            json_path, csv_path = write_results(output, settings, records)
            for line in rerun_lines(output, args.output, settings, records):
                print(line)
        except BaseException as error:
            stop = stop_within(error)
            if stop is None:
                raise
            sys.stdout.flush()
            print(f"\nstress: stopped by {stop}: {_kept(journal, cases)}",
                  file=sys.stderr)
            return stop.code
    failed = sum(bool(violations(r)) for r in records)
    print(f"{failed} of {len(records)} cases broke an invariant; wrote "
          f"{json_path} and {csv_path}")
    return exit_code(records)


def _kept(journal, cases):
    """What a stopped run leaves: the cases finished, in the journal."""
    if journal is None:
        return "no case had run; the journal was not touched"
    lines = journal.path.read_text(encoding="utf-8").splitlines()[1:]
    done = {record["case"] for record in map(_record_from_line, lines)
            if record is not None}
    return (f"{len(done)} of {cases} case(s) finished, kept in "
            f"{journal.path}; the cases under way were cancelled; "
            "--resume runs the rest")
