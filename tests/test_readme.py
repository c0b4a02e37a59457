"""Every Python example of README.md runs as a user would paste it.

Each ```python block runs in a process of its own, in a fresh folder
that holds `my_robot.yaml` (examples/own_robot's description, with its
model beside it), the file the README's own-robot example loads.
"""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OWN_ROBOT = ROOT / "examples" / "own_robot"


def python_blocks(text):
    """The ```python blocks of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```", text, re.M | re.S)


BLOCKS = python_blocks((ROOT / "README.md").read_text())


def test_python_blocks_are_found():
    text = "x\n```python\na = 1\n```\n```bash\nls\n```\n```python\nb = 2\n```\n"
    assert python_blocks(text) == ["a = 1\n", "b = 2\n"]
    assert len(BLOCKS) >= 5


@pytest.mark.parametrize("block", BLOCKS,
                         ids=[f"block{i + 1}" for i in range(len(BLOCKS))])
def test_readme_block_runs(block, tmp_path):
    shutil.copy(OWN_ROBOT / "omni_arm.robot.yaml", tmp_path / "my_robot.yaml")
    shutil.copy(OWN_ROBOT / "omni_arm.urdf", tmp_path)
    result = subprocess.run([sys.executable, "-c", block], cwd=tmp_path,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f"{block}\n{result.stderr}"


def test_every_stage_the_readme_names_is_imported_from_the_stages():
    """"Import them from `drake_wbc.stages`": every stage the README's
    controller section lists (ExternalWrenchEstimator was not there)."""
    import drake_wbc.stages

    text = (ROOT / "README.md").read_text()
    listed = text[text.index("### The controller"):
                  text.index("Import them from `drake_wbc.stages`")]
    names = set(re.findall(r"`([A-Z][A-Za-z]+)`", listed))
    assert "ExternalWrenchEstimator" in names and len(names) >= 15
    missing = sorted(n for n in names if n not in drake_wbc.stages.__all__)
    # Drake's own names, which the section mentions beside the stages.
    assert missing == ["LinearSystem", "Linearize", "TemplateSystem"]


def test_the_stages_the_readme_says_are_built_without_arguments_are():
    """Every stage is constructible with no arguments but the three that
    the README names, which need the robot's footprint or their inputs."""
    import drake_wbc.stages

    needs = {"BaseCdmp", "BaseCommandLimiter", "InputGuard"}
    for name in drake_wbc.stages.__all__:
        if name.endswith("_") or name == "GuardedInput":
            continue
        stage = getattr(drake_wbc.stages, name)
        if name in needs:
            with pytest.raises((ValueError, TypeError)):
                stage()
        else:
            assert stage().num_output_ports() > 0, name
