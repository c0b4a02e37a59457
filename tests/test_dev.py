"""dev.py, the entry point of a fresh clone: a failed install ends in one
line saying what failed, not in a traceback."""

import importlib.util
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def dev(tmp_path, monkeypatch):
    """dev.py as a module, its .venv moved into `tmp_path`."""
    spec = importlib.util.spec_from_file_location("dev", ROOT / "dev.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, "ROOT", tmp_path)
    monkeypatch.setattr(module, "VENV", tmp_path / ".venv")
    monkeypatch.setattr(module, "STAMP", tmp_path / ".venv" / "stamp")
    monkeypatch.setattr(module, "_requirements_hash", lambda: "digest")
    return module


def test_a_failed_pip_install_is_one_line(dev, monkeypatch):
    python = dev.VENV / "bin" / "python"
    python.parent.mkdir(parents=True)
    python.write_text("")
    monkeypatch.setattr(dev.subprocess, "run", lambda *a, **k:
                        subprocess.CompletedProcess(a, 1))
    with pytest.raises(SystemExit) as stop:
        dev.ensure_installed()
    assert stop.value.code == (
        "dev.py: installing into .venv failed (pip exited 1; its messages "
        "above say why).")
    assert not dev.STAMP.exists()


def test_a_python_without_ensurepip_is_told_what_to_install(dev,
                                                            monkeypatch):
    def create(self, folder):
        raise subprocess.CalledProcessError(1, ["python", "-m", "ensurepip"])

    monkeypatch.setattr(dev.venv.EnvBuilder, "create", create)
    with pytest.raises(SystemExit) as stop:
        dev.ensure_installed()
    assert "python3-venv" in stop.value.code
    assert stop.value.code.startswith("dev.py: creating .venv failed: ")
