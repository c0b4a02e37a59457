"""The dependency range says what is tested: pyproject.toml pins drake to
one version, the one this suite runs on (the range drake>=1.51 gave a
user on Python 3.12 or newer drake 1.58, which no test had run)."""

import tomllib
from importlib.metadata import version
from pathlib import Path

from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def project():
    return tomllib.loads(PYPROJECT.read_text(encoding="utf-8"))["project"]


def test_drake_is_pinned_to_the_version_the_suite_runs_on():
    drake = [Requirement(text) for text in project()["dependencies"]
             if Requirement(text).name == "drake"]
    assert len(drake) == 1
    (pin,) = drake[0].specifier
    assert pin.operator == "==", (
        f"drake{drake[0].specifier} is a range: pin the version the suite "
        "has run (README.md, 'Trying a newer drake')")
    installed = version("drake")
    assert installed == pin.version, (
        f"the suite runs on drake {installed}, but pyproject.toml pins "
        f"{pin.version}: once the whole suite passes on {installed}, move "
        "the pin (README.md, 'Trying a newer drake')")


def test_the_python_range_ends_where_the_pinned_drake_has_wheels():
    python = SpecifierSet(project()["requires-python"])
    assert "3.11" in python and "3.13" in python
    assert "3.14" not in python
