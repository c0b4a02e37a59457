"""Interleaved timing, its statistics, and what the figures were measured on.

Every benchmark of drake_wbc.bench times its contenders with `interleave`:
within each repetition every contender runs once, in an order rotated
from one repetition to the next, so that a burst of load from elsewhere
on the machine falls on all of them alike rather than on whichever ran
at that moment. Each contender is a callable that does a batch of work
and returns how many units (solves, ticks) it did; the figures recorded
for a repetition are the wall time per unit and the CPU time of the
calling thread per unit (time.thread_time_ns): the second leaves out
the time the thread waited while another process held the core, so it
moves less when the machine is shared; the two differ by that wait.
"""

import os
import platform
import sys
import time
from importlib import metadata

import numpy as np

from drake_wbc.math.validation import whole_number

PERCENTILES = (10, 25, 50, 75, 90)
"""The percentiles that `summarize` reports."""

VERSIONED_PACKAGES = ("drake", "numpy", "scipy", "qpsolvers", "osqp",
                      "clarabel", "proxsuite", "daqp", "quadprog")
"""The packages whose versions go with the figures."""


class Timings(dict):
    """What `interleave` returns: name -> wall-clock seconds per unit,
    and in `cpu` the thread's CPU seconds per unit."""

    cpu: dict


def interleave(contenders, repeats, warmup=1):
    """Times `contenders` round-robin, `repeats` times each.

    Args:
        contenders: dict name -> callable() that does one batch of work
            and returns the number of units it did (> 0).
        repeats: number of timed repetitions (>= 1).
        warmup: untimed repetitions first (>= 0), for caches, lazy
            imports and allocations.

    Returns:
        dict name -> (repeats,) array of wall-clock seconds per unit, one
        entry per repetition; its attribute `cpu` holds the same for the
        thread's CPU time (a dict of the same shape).

    Raises:
        ValueError: if repeats or warmup is not a whole number in range,
            or a contender reports no unit of work.
    """
    repeats = whole_number("repeats", repeats, minimum=1)
    warmup = whole_number("warmup", warmup, minimum=0)
    names = list(contenders)
    for _ in range(warmup):
        for name in names:
            contenders[name]()
    times = Timings({name: np.empty(repeats) for name in names})
    times.cpu = {name: np.empty(repeats) for name in names}
    clock, cpu_clock = time.perf_counter_ns, time.thread_time_ns
    for r in range(repeats):
        shift = r % len(names)
        for name in names[shift:] + names[:shift]:
            start, cpu_start = clock(), cpu_clock()
            units = contenders[name]()
            elapsed, cpu = clock() - start, cpu_clock() - cpu_start
            if not units or units <= 0:
                raise ValueError(
                    f"contender {name!r} returned units = {units!r}, which "
                    "is not allowed: must return the number of units done "
                    "(> 0)")
            times[name][r] = 1e-9 * elapsed / units
            times.cpu[name][r] = 1e-9 * cpu / units
    return times



def summarize(samples):
    """Median and spread of positive `samples` (e.g. seconds per solve).

    Returns:
        dict with `median`, `p10`, `p25`, `p75`, `p90`, `iqr` (p75 - p25),
        `min` and `n`, plain floats (int for `n`).
    """
    samples = np.asarray(samples, dtype=float)
    values = np.percentile(samples, PERCENTILES)
    stats = {f"p{p}": float(v) for p, v in zip(PERCENTILES, values,
                                                strict=True)}
    stats["median"] = stats.pop("p50")
    stats["iqr"] = stats["p75"] - stats["p25"]
    stats["min"] = float(samples.min())
    stats["n"] = int(samples.size)
    return stats


def scaled(stats, factor):
    """`stats` (from summarize) with every time figure times `factor`."""
    return {k: (v if k == "n" else v * factor) for k, v in stats.items()}


def cpu_model():
    """The CPU's model name (from /proc/cpuinfo on Linux)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment():
    """What the figures were measured on: versions and the machine.

    Returns:
        dict with `python`, `packages` (name -> version, or None when not
        installed), `cpu_model`, `cpu_count`, `platform`.
    """
    packages = {}
    for name in VERSIONED_PACKAGES:
        try:
            packages[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            packages[name] = None
    return {
        "python": sys.version.split()[0],
        "packages": packages,
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
    }
