#!/usr/bin/env python3
"""Compares every scenario's logs between two checkouts of drake_wbc.

Runs `drake-wbc run NAME --no-replay` for each scenario (full duration,
every variant) in this checkout and in another commit (checked out beside
it as a detached git worktree), then compares every logged signal of
every run, sample by sample:

    |a - b| <= max(rtol * max(|a|, |b|), atol)   (rtol 1e-9, atol 1e-12)

and prints, per run and signal, the largest difference where one exceeds
the tolerance. Exit code 0 when all agree, 1 otherwise.

    python tools/compare_logs.py --against c7eced0            # all
    python tools/compare_logs.py --against main fixed_point   # one
    python tools/compare_logs.py --against REF --keep out/compare

Each side runs with the same Python (this one) and its own source tree
first on sys.path, so the comparison is of the code alone. `--keep DIR`
keeps the logs (DIR/ours, DIR/theirs) and reuses those of the other
commit found there for the same commit id.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
NOT_SCENARIOS = ("controller",)
"""The files of diagrams/ that are not scenarios (the controller's
defaults)."""


def common_scenarios(checkout):
    """Every scenario of diagrams/ in both this checkout and `checkout`,
    in order (a scenario added since is not in the other one)."""
    def names(root):
        return {path.stem for path in (root / "diagrams").glob("*.yaml")
                if path.stem not in NOT_SCENARIOS}

    return sorted(names(ROOT) & names(checkout))


def _entry_point(checkout):
    """The `drake-wbc` entry point (module, function) of a checkout."""
    project = tomllib.loads((checkout / "pyproject.toml").read_text())
    module, function = project["project"]["scripts"]["drake-wbc"].split(":")
    return module, function


def run_scenarios(checkout, names, output):
    """Runs each scenario of `names` in `checkout`, logs under `output`."""
    module, function = _entry_point(checkout)
    env = dict(os.environ, PYTHONPATH=str(checkout), MPLBACKEND="Agg")
    code = (f"import sys; from {module} import {function} as main; "
            f"sys.exit(main(sys.argv[1:]))")
    for name in names:
        target = output / name
        if any(target.glob("log_*.npz")):
            continue
        print(f"  {checkout.name}: {name} ...", flush=True)
        subprocess.run(
            [sys.executable, "-c", code, "run", name, "--no-replay",
             "--output", str(target)],
            cwd=checkout, env=env, check=True, stdout=subprocess.DEVNULL)


def compare_run(ours, theirs, rtol, atol):
    """Differences beyond tolerance between two log files: a list of
    (signal, what differs, max abs diff, max rel diff). Logs of different
    lengths differ, and their common samples are compared too (a
    difference there is a second entry of the signal)."""
    a, b = np.load(ours), np.load(theirs)
    problems = []
    for key in sorted(set(a.files) | set(b.files)):
        if key not in a.files or key not in b.files:
            problems.append((key, "missing on one side", np.inf, np.inf))
            continue
        x, y = a[key], b[key]
        if x.shape != y.shape:
            if key == "header" or not x.ndim or x.shape[1:] != y.shape[1:]:
                problems.append((key, f"shape {x.shape} vs {y.shape}",
                                 np.inf, np.inf))
                continue
            # Logs of different lengths: the extra samples are a
            # difference, and the common ones are compared below.
            n = min(len(x), len(y))
            problems.append((key, f"{len(x)} samples here, {len(y)} there "
                                  f"(the first {n} compared)",
                             np.inf, np.inf))
            x, y = x[:n], y[:n]
        if key == "header":
            # The columns must agree; the prose (units, where SIGNALS
            # lives) may change with the code.
            if json.loads(str(x))["signals"] != json.loads(str(y))["signals"]:
                problems.append((key, "columns differ", np.inf, np.inf))
            continue
        if x.dtype.kind not in "fiu":
            if not np.array_equal(x, y):
                problems.append((key, "values differ", np.inf, np.inf))
            continue
        x, y = x.astype(float), y.astype(float)
        same = (x == y) | (np.isnan(x) & np.isnan(y))
        diff = np.where(same, 0.0, np.abs(x - y))
        scale = np.maximum(np.abs(x), np.abs(y))
        bad = diff > np.maximum(rtol * scale, atol)
        if bad.any():
            rel = np.where(scale > 0, diff / np.where(scale > 0, scale, 1),
                           0.0)
            problems.append((key, f"{int(bad.sum())} samples",
                             float(diff.max()), float(rel.max())))
    return problems


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenarios", nargs="*",
                        help="scenario names (default: every scenario of "
                             "both checkouts)")
    parser.add_argument("--against", required=True,
                        help="the other commit (any git revision)")
    parser.add_argument("--keep", type=Path,
                        help="keep the logs here (and reuse the other "
                             "commit's)")
    parser.add_argument("--rtol", type=float, default=1e-9)
    parser.add_argument("--atol", type=float, default=1e-12)
    args = parser.parse_args(argv)
    commit = subprocess.run(
        ["git", "rev-parse", args.against], cwd=ROOT, check=True,
        capture_output=True, text=True).stdout.strip()
    with tempfile.TemporaryDirectory() as scratch:
        keep = args.keep or Path(scratch)
        ours_dir, theirs_dir = keep / "ours", keep / f"theirs_{commit[:12]}"
        worktree = Path(scratch) / f"at_{commit[:12]}"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet",
                        str(worktree), commit], cwd=ROOT, check=True)
        args.scenarios = args.scenarios or common_scenarios(worktree)
        try:
            run_scenarios(worktree, args.scenarios, theirs_dir)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force",
                            str(worktree)], cwd=ROOT, check=True)
        if ours_dir.exists():
            subprocess.run(["rm", "-rf", str(ours_dir)], check=True)
        run_scenarios(ROOT, args.scenarios, ours_dir)
        failures = 0
        for name in args.scenarios:
            theirs = sorted((theirs_dir / name).glob("log_*.npz"))
            ours = sorted((ours_dir / name).glob("log_*.npz"))
            if [p.name for p in theirs] != [p.name for p in ours]:
                print(f"{name}: runs differ: {[p.name for p in ours]} vs "
                      f"{[p.name for p in theirs]}")
                failures += 1
                continue
            for mine, other in zip(ours, theirs, strict=True):
                problems = compare_run(mine, other, args.rtol, args.atol)
                run = f"{name}/{mine.stem}"
                if not problems:
                    print(f"{run}: agree")
                    continue
                failures += 1
                for key, what, absolute, relative in problems:
                    print(f"{run}: {key}: {what}, max |diff| "
                          f"{absolute:.3g}, max rel {relative:.3g}")
        print("all logs agree" if not failures
              else f"{failures} runs differ")
        return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
