"""The loader against files written to hurt it: aliases that multiply,
deep nesting, duplicate keys, bytes that are not UTF-8, huge files,
absurd numbers. Each is a ValueError naming the file, the line or the
field's dotted path and what is allowed, raised in a moment, never a
traceback from deep in yaml or pydrake, never minutes of CPU."""

import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from drake_wbc.controller import load_controller_parameters
from drake_wbc.experiments.scenario import load_scenario
from drake_wbc.math.loading import (
    MAX_ALIASES,
    MAX_BYTES,
    MAX_DEPTH,
    MAX_NODES,
    screen,
)

ROOT = Path(__file__).resolve().parents[1]


def laughs(levels=9, width=10):
    """A "billion laughs" inside a known field: `width` ** `levels` ones
    written in a few hundred bytes."""
    items = [f"&a0 [{', '.join(['1'] * width)}]"]
    for i in range(1, levels):
        items.append(f"&a{i} [{', '.join([f'*a{i - 1}'] * width)}]")
    return f"arm_cdmp:\n  F_d: [{', '.join(items)}]\n"


def refused(load, text, tmp_path, name="hostile.yaml"):
    """The message of the ValueError that `load` raises on `text` written
    to a file (checked to name the file, and to be short)."""
    file = tmp_path / name
    file.write_bytes(text if isinstance(text, bytes) else text.encode())
    start = time.perf_counter()
    with pytest.raises(ValueError) as error:
        load(path=file)
    assert time.perf_counter() - start < 5.0
    message = str(error.value)
    assert message.startswith(f"{file}: "), message
    assert len(message) < 600, message
    return message


def test_a_billion_laughs_is_refused_in_a_moment_without_expanding():
    """On the loader of before, this burned 45 s of CPU and ended in a
    MemoryError (the error message rendered the expanded value); a child
    process with a memory limit keeps a regression from hurting the run."""
    program = textwrap.dedent(f"""
        import resource, sys, time
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
        from drake_wbc.controller import load_controller_parameters
        start = time.perf_counter()
        try:
            load_controller_parameters(text={laughs()!r})
        except ValueError as error:
            print(f"{{time.perf_counter() - start:.3f}}", error)
    """)
    result = subprocess.run([sys.executable, "-c", program], cwd=ROOT,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr[-2000:]
    seconds, message = result.stdout.split(" ", 1)
    assert float(seconds) < 1.0
    assert "arm_cdmp.F_d[" in message and f"{MAX_NODES} values" in message
    assert len(message) < 400


@pytest.mark.parametrize("load", [load_controller_parameters, load_scenario])
def test_aliases_are_limited_in_number_and_never_cyclic(load, tmp_path):
    many = "description: &d x\n_other: [" + ", ".join(
        ["*d"] * (MAX_ALIASES + 1)) + "]\n"
    message = refused(load, many, tmp_path)
    assert f"at most {MAX_ALIASES} aliases" in message
    assert "_other[100] = alias *d" in message
    message = refused(load, "_loop: &x [1, *x]\n", tmp_path)
    assert "_loop[1] = alias *x" in message and "holds it" in message
    message = refused(load, "_a: *nowhere\n", tmp_path)
    assert "*nowhere" in message and "defined before it" in message


def test_a_few_aliases_and_merge_keys_still_load():
    """Anchors shared between fields, a private template at the top level
    (Drake drops keys that start with _) and a merge key that overrides."""
    params = load_controller_parameters(text=textwrap.dedent("""
        _dmp: &dmp {alpha_z: 20.0, tau: 1.0}
        _arm: &arm {alpha_z: 30.0}
        base_cdmp: {dmp: {<<: *dmp, alpha_z: 10.0}}
        whole_body_cdmp: {dmp: *dmp}
        arm_cdmp: {dmp: *arm}
    """))
    assert params.arm_cdmp.dmp.alpha_z == 30.0
    assert params.base_cdmp.dmp.alpha_z == 10.0
    assert params.whole_body_cdmp.dmp.alpha_z == 20.0


@pytest.mark.parametrize("opening, closing", [("[", "]"), ("{a: ", "}")])
def test_deep_nesting_is_refused(opening, closing, tmp_path):
    """500 nested brackets gave a RecursionError traceback."""
    text = "time_step: " + opening * 500 + "1" + closing * 500 + "\n"
    for load in (load_controller_parameters, load_scenario):
        message = refused(load, text, tmp_path)
        assert f"nested deeper than {MAX_DEPTH} levels" in message
        assert message.split(": ")[2].startswith("time_step")
    inside = "time_step: " + "[" * (MAX_DEPTH - 1) + "]" * (MAX_DEPTH - 1)
    message = refused(load_controller_parameters, inside, tmp_path)
    assert "time_step = " in message and "nested" not in message


def test_a_file_that_is_not_utf8_is_named_with_its_line(tmp_path):
    text = "description: caf\xe9\n".encode("latin-1")
    message = refused(load_scenario, b"# a scenario\n" + text, tmp_path)
    assert "line 2, column 17: byte 0xe9 is not allowed" in message
    assert "UTF-8" in message


def test_a_huge_file_is_refused_unread(tmp_path):
    big = b"# " + b"x" * MAX_BYTES + b"\n"
    message = refused(load_controller_parameters, big, tmp_path)
    assert f"at most {MAX_BYTES} bytes" in message
    with pytest.raises(ValueError, match="bytes of YAML"):
        load_controller_parameters(text=big.decode())


def test_too_many_values_are_refused(tmp_path):
    text = "_values: [" + ", ".join(["0"] * MAX_NODES) + "]\n"
    message = refused(load_controller_parameters, text, tmp_path)
    assert f"beyond {MAX_NODES} values" in message


DUPLICATES = [
    (load_controller_parameters, "time_step: 0.01\ntime_step: 0.02\n",
     ["line 2, column 1: key 'time_step' again (first at line 1)"]),
    (load_scenario, "controller:\n  distributor:\n    null_space_gain: "
     "0.1\n    band: {lower: 0.035}\n    null_space_gain: 0.2\n",
     ["line 5, column 5: key 'controller.distributor.null_space_gain' "
      "again (first at line 3)"]),
    (load_scenario, "scene:\n  people:\n  - {name: a, times: [0], "
     "waypoints: [[3, 3]], name: b}\n",
     ["line 3, column ", "key 'scene.people[0].name' again (first at "
      "line 3)"]),
]


@pytest.mark.parametrize("load, text, fragments", DUPLICATES)
def test_a_duplicate_key_names_the_key_and_its_lines(load, text, fragments,
                                                     tmp_path):
    """Duplicate keys passed silently (the last one won)."""
    message = refused(load, text, tmp_path)
    for fragment in fragments:
        assert fragment in message, message
    assert "a key may appear only once in a mapping" in message


def test_a_mapping_where_a_list_is_expected_says_so(tmp_path):
    message = refused(load_scenario, (
        "scene:\n  cylinders: {name: p, position: [2, 0], radius: 0.1}\n"),
        tmp_path)
    assert "scene.cylinders = {name: 'p', position: [2, 0], radius: 0.1}" \
        in message
    assert "must be a list of CylinderObstacle" in message
    message = refused(load_scenario, "task: {reference_velocity: {times: "
                      "{a: 1}}}\n", tmp_path)
    assert "task.reference_velocity.times = {a: 1}" in message
    assert "must be a list" in message


def test_a_document_that_is_not_a_mapping_says_what_is_allowed(tmp_path):
    message = refused(load_controller_parameters, "[1, 2]\n", tmp_path)
    assert "the document = [1, 2] is not allowed" in message
    assert "mapping of the fields of ControllerParameters" in message


def test_long_values_are_shortened_in_messages(tmp_path):
    values = ", ".join(str(i) for i in range(5000))
    message = refused(load_scenario, f"description: [{values}]\n", tmp_path)
    assert "description = [0, 1, 2" in message
    assert " ... " in message
    zeros = ", ".join(["0"] * 5000)
    message = refused(load_scenario, (
        f"scene: {{people: [{{name: a, times: [{zeros}]}}]}}\n"), tmp_path)
    assert "scene.people[0].times = [0.0, 0.0" in message
    assert "characters) is not allowed: must be strictly increasing" in \
        message


ABSURD = [
    # (scenario text, fragments of the message)
    ("controller: {whole_body_cdmp: {dmp: {alpha_z: 1e300}}}",
     ["controller.whole_body_cdmp.dmp.alpha_z = 1e+300", "Nyquist"]),
    ("controller: {base_cdmp: {dmp: {tau: 1.0e-300}}}",
     ["controller.base_cdmp.dmp.alpha_z = 25.0", "tau = 1e-300", "Nyquist"]),
    ("controller: {arm_cdmp: {dmp: {alpha_z: 1e400}}}",
     ["controller.arm_cdmp.dmp.alpha_z = inf", "finite"]),
    ("controller: {whole_body_cdmp: {k_hri: 1e300}}",
     ["controller.whole_body_cdmp.k_hri = 1e+300", "at most 1.0 m/(N s)"]),
    ("controller: {base_cdmp: {dmp: {num_basis: 100000000}}}",
     ["controller.base_cdmp.dmp.num_basis = 100000000", "at most 1000"]),
    ("station: {wrist: {rate: 1e300}}",
     ["station.wrist.rate = 1e+300 Hz",
      "at most 1 / station.time_step = 1000 Hz"]),
    ("station: {lidar: {rate: 1e6}}",
     ["station.lidar.rate = 1000000.0 Hz", "at most 1 / station.time_step"]),
    ("station: {lidar: {num_beams: 1000000000}}",
     ["station.lidar.num_beams = 1000000000", "at most 10000"]),
    ("station: {time_step: 1.0e-300}",
     ["station.time_step = 1e-300 s", "at least 1e-05 s (10 us)"]),
    ("station: {arm: {servo_frequency: 1.0e-300}}",
     ["station.arm.servo_frequency = 1e-300 Hz", "at least 1.0 Hz"]),
    ("station: {initial_base_pose: [1e300, 0, 0]}",
     ["station.initial_base_pose = [1e+300, 0.0, 0.0]", "+-1000 m"]),
    ("station: {initial_base_pose: [0, 0, 1e300]}",
     ["station.initial_base_pose[2] = 1e+300 rad", "+-2 pi rad"]),
    ("scene: {hand: {times: [0, 1], forces: [[0, 0, 0], [1e300, 0, 0]]}}",
     ["scene.hand.forces[1][0] = 1e+300 N", "+-1000 N"]),
    ("scene: {cylinders: [{name: p, position: [5, 5], height: 1e300}]}",
     ["scene.cylinders[0].height = 1e+300", "+-1000 m"]),
    ("scene: {boxes: [{name: b, center: [1e300, 5, 0]}]}",
     ["scene.boxes[0].center = [1e+300, 5.0, 0.0]", "+-1000 m"]),
    ("scene: {people: [{name: a, times: [0], waypoints: [[1e300, 3]]}]}",
     ["scene.people[0].waypoints = [[1e+300, 3.0]]", "+-1000 m"]),
    ("outputs: {log_period: 1.0e-300}",
     ["outputs.log_period = 1e-300 s", "at least the station's step"]),
    ("outputs: {replay_frame_rate: 1e300}",
     ["outputs.replay_frame_rate = 1e+300 Hz", "at most 1 / "]),
]


@pytest.mark.parametrize("text, fragments", ABSURD)
def test_absurd_numbers_are_refused_with_a_reason(text, fragments, tmp_path):
    """Each of these but the infinite one (refused already) was accepted
    before, and then overflowed the DMP's discretisation, stalled the
    simulation, aborted Drake's geometry or filled the memory."""
    message = refused(load_scenario, text + "\n", tmp_path)
    for fragment in fragments:
        assert fragment in message, message


def test_the_scenarios_of_the_repository_pass_the_screen():
    for path in sorted((ROOT / "diagrams").glob("*.yaml")):
        assert 0 < screen(path.read_text(encoding="utf-8")) < 1000, path


def expanded_size(value):
    """Nodes of plain YAML data, shared parts counted at each use."""
    if isinstance(value, dict):
        return 1 + sum(1 + expanded_size(v) for v in value.values())
    if isinstance(value, list):
        return 1 + sum(expanded_size(v) for v in value)
    return 1


leaves = st.one_of(st.integers(-5, 5), st.text("abc", max_size=3),
                   st.booleans(), st.none())
trees = st.recursive(leaves, lambda inner: st.one_of(
    st.lists(inner, max_size=4),
    st.dictionaries(st.text("xyz", min_size=1, max_size=3), inner,
                    max_size=4)), max_leaves=20)


@settings(max_examples=60, deadline=None)
@given(tree=trees, shared=st.integers(0, 3))
def test_the_expanded_size_matches_the_data_pyyaml_builds(tree, shared):
    """An independent count: PyYAML's dump writes anchors and aliases for
    the parts used more than once; `screen` counts them expanded."""
    document = {"root": tree}
    for i in range(shared):  # the tree used again, as aliases
        document[f"again_{i}"] = [tree, document["root"]]
    text = yaml.safe_dump(document)
    assert screen(text) == expanded_size(yaml.safe_load(text))
