#!/usr/bin/env python3
"""One entry point for a fresh clone: makes `.venv`, installs, runs.

    python3 dev.py run     # the main job: drake-wbc run (the default scenario)
    python3 dev.py test    # the whole test suite (extra args go to pytest)
    python3 dev.py lint    # ruff check
    python3 dev.py shell   # print how to activate the environment

The first call creates `.venv` next to this file and installs the project
into it in editable mode with its test extras; later calls reuse it and
reinstall only when pyproject.toml has changed. Needs only Python >= 3.11
with the standard library's venv and pip.
"""

import hashlib
import os
import subprocess
import sys
import time
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".drake_wbc_installed"
EXTRAS = "dev"


def _venv_bin(name):
    sub = "Scripts" if os.name == "nt" else "bin"
    return VENV / sub / name


def _requirements_hash():
    return hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()


def ensure_installed():
    """Creates and fills `.venv` unless it is already up to date."""
    # dev.py runs under whatever python3 the user has, so it checks.
    if sys.version_info < (3, 11):  # noqa: UP036
        sys.exit(
            f"dev.py: Python >= 3.11 is required, this is "
            f"{sys.version.split()[0]} ({sys.executable})."
        )
    digest = _requirements_hash()
    if STAMP.exists() and STAMP.read_text().strip() == digest:
        return
    start = time.monotonic()
    if not _venv_bin("python").exists():
        print(f"dev.py: creating {VENV.relative_to(ROOT)} ...", flush=True)
        try:
            venv.EnvBuilder(with_pip=True).create(VENV)
        except subprocess.CalledProcessError as error:  # e.g. no ensurepip
            sys.exit(
                f"dev.py: creating {VENV.relative_to(ROOT)} failed: "
                f"{' '.join(map(str, error.cmd))} exited "
                f"{error.returncode} (on Debian or Ubuntu, install the "
                "python3-venv package; then remove .venv and run again)."
            )
    print(
        "dev.py: installing drake_wbc and its dependencies "
        "(drake, numpy, scipy, matplotlib, lcm; about a minute the first "
        "time) ...",
        flush=True,
    )
    code = subprocess.run(
        [
            str(_venv_bin("python")), "-m", "pip", "install",
            "--disable-pip-version-check", "--quiet",
            "--editable", f".[{EXTRAS}]",
        ],
        cwd=ROOT,
    ).returncode
    if code != 0:  # pip has said why (no network, no wheel for this Python)
        sys.exit(f"dev.py: installing into {VENV.relative_to(ROOT)} failed "
                 f"(pip exited {code}; its messages above say why).")
    STAMP.write_text(digest + "\n")
    print(f"dev.py: installed in {time.monotonic() - start:.0f} s", flush=True)


def _run(argv):
    """Runs a program of the environment and returns its exit code."""
    return subprocess.run(argv, cwd=ROOT).returncode


def main(args):
    command, rest = (args[0], args[1:]) if args else ("run", [])
    if command not in ("run", "test", "lint", "shell"):
        sys.exit(
            f"dev.py: unknown command {command!r}; "
            "use one of: run, test, lint, shell."
        )
    ensure_installed()
    if command == "run":
        return _run([str(_venv_bin("drake-wbc")), "run", *rest])
    if command == "test":
        return _run([str(_venv_bin("python")), "-m", "pytest", *rest])
    if command == "lint":
        return _run([str(_venv_bin("ruff")), "check", ".", *rest])
    print(f"source {_venv_bin('activate')}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
