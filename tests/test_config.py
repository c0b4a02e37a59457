"""The controller's parameters from YAML: diagrams/controller.yaml holds the
defaults in full, partial files override only what they name, and every
bad value or key is reported with the file and the field's path."""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractValue
from pydrake.common.yaml import yaml_dump_typed, yaml_load_file

from drake_wbc.controller import (
    ControllerParameters,
    build_controller,
    load_controller_parameters,
)
from drake_wbc.math.capability import CapabilityBand
from drake_wbc.math.cdmp import AdmittanceCouplingParameters, ArmCdmpParameters
from drake_wbc.math.dmp import DmpParameters
from drake_wbc.math.filtering import BaseFilterParameters
from drake_wbc.math.motion_mode import MotionMode
from drake_wbc.math.validation import validate
from drake_wbc.math.workspace import LocalWorkspace, WorkspaceAdapterParameters
from drake_wbc.stages import BaseVelocityFilter, WorkspaceAdapter

CONTROLLER_FILE = Path(__file__).parents[1] / "diagrams" / "controller.yaml"


def assert_same(actual, expected, path="params"):
    """Field by field (recursively), numpy arrays with np.array_equal."""
    if dataclasses.is_dataclass(expected):
        assert type(actual) is type(expected), path
        for item in dataclasses.fields(expected):
            assert_same(getattr(actual, item.name),
                        getattr(expected, item.name), f"{path}.{item.name}")
    elif isinstance(expected, np.ndarray):
        assert isinstance(actual, np.ndarray), path
        assert np.array_equal(actual, expected), path
        assert actual.dtype == expected.dtype, path
    else:
        assert actual == expected, path
        assert type(actual) in (type(expected), float), path


def assert_every_field_written(document, params, path="params"):
    """The YAML mapping `document` has exactly the fields of `params`, at
    every level."""
    names = [item.name for item in dataclasses.fields(params)]
    assert list(document) == names, path
    for name in names:
        value = getattr(params, name)
        if dataclasses.is_dataclass(value):
            assert_every_field_written(document[name], value,
                                       f"{path}.{name}")


def test_the_file_holds_the_defaults_in_full():
    defaults = ControllerParameters()
    assert_every_field_written(yaml_load_file(CONTROLLER_FILE), defaults)
    loaded = load_controller_parameters(path=CONTROLLER_FILE)
    assert_same(loaded, defaults)
    assert loaded == defaults
    assert loaded.workspace.mode is MotionMode.LOCO_MANIPULATION
    assert not loaded.arm_cdmp.S_m.flags.writeable  # normalised again


def test_parameters_compare_by_value_their_arrays_too():
    """ControllerParameters() == ControllerParameters(): the two parameter
    classes with array fields (ArmCdmpParameters' S_m and F_d,
    AdmittanceCouplingParameters' D_a and F_d) compare them by value,
    shape included; like the other parameters (mutable), they are not
    hashable."""
    assert ControllerParameters() == ControllerParameters()
    other = ControllerParameters()
    other.arm_cdmp = ArmCdmpParameters(F_d=[-5.0, 0, 0, 0, 0, 0])
    assert other != ControllerParameters()
    assert AdmittanceCouplingParameters() == AdmittanceCouplingParameters()
    assert AdmittanceCouplingParameters(F_d=[0.0, 1.0]) \
        != AdmittanceCouplingParameters(F_d=[0.0, 0.0])
    # 0.01 as a number and as a matrix are not the same parameters.
    assert AdmittanceCouplingParameters() \
        != AdmittanceCouplingParameters(D_a=[[0.01]])
    assert ArmCdmpParameters() != "ArmCdmpParameters()"
    for params in (ControllerParameters(), ArmCdmpParameters(),
                   AdmittanceCouplingParameters()):
        with pytest.raises(TypeError, match="unhashable"):
            hash(params)


def test_the_file_loads_from_a_string_too():
    assert_same(load_controller_parameters(text=CONTROLLER_FILE.read_text()),
                ControllerParameters())


def test_a_partial_file_overrides_only_its_fields(tmp_path):
    file = tmp_path / "partial.yaml"
    file.write_text("time_step: 0.005\ndistributor: {null_space_gain: 0.1}\n")
    loaded = load_controller_parameters(path=file)
    expected = ControllerParameters()
    expected.time_step = 0.005
    expected.distributor.null_space_gain = 0.1
    assert_same(loaded, expected)


def test_an_empty_document_gives_the_defaults():
    for text in ("", "# nothing to change\n", "{}"):
        assert_same(load_controller_parameters(text=text),
                    ControllerParameters())


def test_every_field_type_survives_a_round_trip():
    params = ControllerParameters(time_step=0.005, phri_switch=1.0)
    params.capability_band = CapabilityBand(0.03, 0.04)
    params.capability.joint_limit_gain = 2.0e4
    params.workspace.mode = "intuitive-phri"
    params.workspace.workspace = LocalWorkspace(extent_upper=0.85)
    params.distributor.damping.threshold = 2.0e-4
    params.base_cdmp.repulsion.half_sizes = (0.5, 0.35)
    params.whole_body_cdmp.dmp.beta_z = 5.0
    params.arm_cdmp.S_m = (0, 1, 1, 1, 1, 1)
    params.arm_cdmp.F_d = (-5, 0, 0, 0, 0, 0.5)
    params.arm_controller.lower = [-3.0] * 6
    params.arm_controller.upper = [3.0] * 6
    params.arm_controller.velocity_limits = [1.0] * 6
    validate(params)
    loaded = load_controller_parameters(text=yaml_dump_typed(params))
    assert_same(loaded, params)
    assert loaded.workspace.mode is MotionMode.INTUITIVE_PHRI
    assert loaded.arm_controller.lower == (-3.0,) * 6


def test_null_sets_an_optional_field_to_none():
    loaded = load_controller_parameters(text=(
        "distributor: {damping: null}\n"
        "base_cdmp: {dmp: {beta_z: 5.0}}\n"))
    assert loaded.distributor.damping is None
    assert loaded.base_cdmp.dmp.beta_z == 5.0
    assert loaded.arm_cdmp.dmp.beta_z is None


def test_a_controller_builds_from_loaded_parameters():
    params = load_controller_parameters(text=(
        "time_step: 0.005\n"
        "workspace: {mode: intuitive-phri}\n"
        "arm_cdmp: {S_m: [0, 1, 1, 1, 1, 1]}\n"))
    controller = build_controller(params)
    stages = controller.stages
    assert stages["workspace"].params.mode is MotionMode.INTUITIVE_PHRI
    for name in ("whole_body_cdmp", "base_cdmp", "base_filter",
                 "base_limiter", "arm_cdmp", "arm_controller", "guard"):
        attribute = stages[name].GetUniquePeriodicDiscreteUpdateAttribute()
        assert attribute.period_sec() == 0.005, name
    np.testing.assert_array_equal(stages["arm_cdmp"].params.S_m,
                                  [0, 1, 1, 1, 1, 1])
    context = controller.diagram.CreateDefaultContext()
    assert context.num_discrete_state_groups() > 0
    build_controller(load_controller_parameters(path=CONTROLLER_FILE))


BAD_VALUES = [
    ("base_filter: {zeta: -1}", "base_filter.zeta = -1.0",
     "greater than 0"),
    ("arm_cdmp: {S_m: [0.5, 1, 1, 1, 1, 1]}", "arm_cdmp.S_m = ",
     "must be 0 or 1"),
    ("arm_cdmp: {S_m: [1, 1]}", "arm_cdmp.S_m = [1. 1.] has shape (2,)",
     "shape (6,)"),
    ("workspace: {mode: flying}", "workspace.mode = 'flying'",
     "'intuitive-phri'"),
    ("capability_band: {lower: 0.05}", "capability_band.lower = 0.05",
     "strictly below"),
    ("phri_switch: 0.5", "phri_switch = 0.5", "0 or 1"),
    ("base_cdmp: {dmp: {num_basis: 0}}", "base_cdmp.dmp.num_basis = 0",
     "1 or greater"),
    ("distributor: {damping: {threshold: 0}}",
     "distributor.damping.threshold = 0.0", "greater than 0"),
    ("arm_controller: {lower: [0, 0, 0, 0, 0, 0]}",
     "arm_controller.lower = ", "both limits or neither"),
    ("time_step: 0.6", "time_step = 0.6", "Nyquist"),
    ("base_filter: {zeta: fast}", "base_filter.zeta = 'fast'",
     "must be a number"),
    ("workspace: {sigma_xy: [0.5]}", "workspace.sigma_xy = [0.5]",
     "must be a number"),
    ("capability_band: 0.04", "capability_band = 0.04",
     "mapping of the fields of CapabilityBand"),
    ("arm_cdmp: {S_x: 1}", "unknown key 'arm_cdmp.S_x'", "k_p, k_d"),
    ("flying: true", "unknown key 'flying'",
     "time_step, capability_band, phri_switch, capability"),
    # Each value once: the copies the stages' parameters used to hold are
    # unknown keys now (ControllerParameters' time_step, capability_band
    # and phri_switch hold them).
    ("capability: {band: {lower: 0.035, upper: 0.04}}",
     "unknown key 'capability.band'", "joint_limit_gain"),
    ("workspace: {band: {lower: 0.035, upper: 0.04}}",
     "unknown key 'workspace.band'", "mode, sigma_xy, sigma_phi, workspace"),
    ("distributor: {band: {lower: 0.03, upper: 0.04}}",
     "unknown key 'distributor.band'", "null_space_gain"),
    ("whole_body_cdmp: {S_hri: 1.0}", "unknown key 'whole_body_cdmp.S_hri'",
     "k_hri, hri_time_constant, dmp, movement"),
    ("arm_cdmp: {S_hri: 0.0}", "unknown key 'arm_cdmp.S_hri'",
     "k_p, k_d, k_f, S_m, F_d, dmp"),
    ("base_filter: {time_step: 0.01}", "unknown key 'base_filter.time_step'",
     "omega_f, zeta, enabled"),
    ("arm_controller: {time_step: 0.01}",
     "unknown key 'arm_controller.time_step'", "damping"),
]


@pytest.mark.parametrize("text, field, allowed", BAD_VALUES)
def test_bad_values_name_the_file_and_field(tmp_path, text, field, allowed):
    file = tmp_path / "bad.yaml"
    file.write_text(text + "\n")
    with pytest.raises(ValueError) as error:
        load_controller_parameters(path=file)
    message = str(error.value)
    assert message.startswith(f"{file}: "), message
    assert field in message and allowed in message, message
    with pytest.raises(ValueError, match=re.escape(field)):
        load_controller_parameters(text=text)


def test_bad_yaml_and_bad_arguments_are_reported(tmp_path):
    file = tmp_path / "broken.yaml"
    file.write_text("arm_cdmp: [\n")
    with pytest.raises(ValueError, match=f"{re.escape(str(file))}: not "
                       "valid YAML"):
        load_controller_parameters(path=file)
    with pytest.raises(ValueError, match="exactly one"):
        load_controller_parameters()
    with pytest.raises(ValueError, match="exactly one"):
        load_controller_parameters(path=file, text="{}")
    with pytest.raises(FileNotFoundError):
        load_controller_parameters(path=tmp_path / "missing.yaml")


def test_validate_checks_and_normalises_assigned_fields():
    params = ControllerParameters()
    params.arm_cdmp.S_m = [0, 1, 1, 1, 1, 1]
    params.workspace.mode = "manipulation"
    params.arm_controller.velocity_limits = [1.0] * 6
    assert validate(params) is params
    assert isinstance(params.arm_cdmp.S_m, np.ndarray)
    assert not params.arm_cdmp.S_m.flags.writeable
    assert params.workspace.mode is MotionMode.MANIPULATION
    assert params.arm_controller.velocity_limits == (1.0,) * 6
    params.base_cdmp.repulsion.d_min = 0.6
    with pytest.raises(ValueError, match=r"base_cdmp\.repulsion\.d_min = "
                       r"0\.6 is not allowed: must lie in \(0, "
                       r"base_cdmp\.repulsion\.d_th = 0\.5\)"):
        validate(params)
    with pytest.raises(ValueError, match="parameters dataclass"):
        validate("fast")
    params = ControllerParameters()
    params.base_filter = None
    with pytest.raises(ValueError, match="base_filter = None"):
        validate(params)


def test_the_mode_is_still_given_by_name():
    params = WorkspaceAdapterParameters(mode="intuitive-phri")
    assert params.mode is MotionMode.INTUITIVE_PHRI
    assert MotionMode.INTUITIVE_PHRI == "intuitive-phri"
    assert MotionMode("locomotion") is MotionMode.LOCOMOTION


def test_stages_read_their_parameters_when_built():
    # The base filter reads its parameters and its time step when it is
    # built (they were checked where they were made): a later change does
    # not reach it, nor its scalar-converted copies (Drake's copies of
    # its LinearSystem, made of the matrices it was built with).
    params = BaseFilterParameters()
    stage = BaseVelocityFilter(params, time_step=0.005)
    assert stage.params is params
    assert stage.ToAutoDiffXd().GetUniquePeriodicDiscreteUpdateAttribute(
        ).period_sec() == 0.005

    def update(system):
        context = system.CreateDefaultContext()
        system.get_input_port().FixValue(context, [1.0, 0.0, 0.0])
        return ExtractValue(system.EvalUniquePeriodicDiscreteUpdate(
            context).get_vector().CopyToVector()).astype(float).ravel()

    before = update(stage)
    params.zeta = 2.0
    np.testing.assert_array_equal(update(stage), before)
    np.testing.assert_array_equal(update(stage.ToAutoDiffXd()), before)
    workspace = WorkspaceAdapterParameters()
    stage = WorkspaceAdapter(workspace)
    workspace.mode = "manipulation"  # read when the stage was built
    context = stage.CreateDefaultContext()
    assert stage.GetOutputPort("sigma_xy").Eval(context)[0] == 0.5
    controller_params = ControllerParameters()
    controller = build_controller(controller_params)
    controller_params.distributor.null_space_gain = 0.1
    assert controller.stages["distributor"].params.null_space_gain == 0.0


def test_the_controller_hands_each_value_held_once_to_its_stages():
    """One band, one default S_hri, one control period: build_controller
    gives each to every stage that needs it, and their scalar-converted
    copies keep them."""
    band = CapabilityBand(0.03, 0.045)
    params = ControllerParameters(capability_band=band, phri_switch=1.0)
    stages = build_controller(params).stages
    for name in ("capability", "workspace", "distributor"):
        for stage in (stages[name], stages[name].ToAutoDiffXd()):
            assert (stage.band.lower, stage.band.upper) == (0.03, 0.045)
    for name in ("whole_body_cdmp", "arm_cdmp"):
        for stage in (stages[name], stages[name].ToAutoDiffXd()):
            context = stage.CreateDefaultContext()
            assert stage._switch(context) == 1  # the port is unconnected
    (switch,) = [spec for spec in stages["guard"].inputs
                 if spec.name == "phri_switch"]
    defaults = {output[0]: list(output[1]) for output in switch.outputs}
    assert defaults == {"phri_switch.whole_body": [1.0],
                        "phri_switch.arm": [1.0]}


def test_the_dmp_basis_follows_its_fields():
    params = DmpParameters()
    assert params.centres.shape == (20,)
    params.num_basis = 10
    params.alpha_s = 3.0
    expected = DmpParameters(num_basis=10, alpha_s=3.0)
    np.testing.assert_array_equal(params.centres, expected.centres)
    np.testing.assert_array_equal(params.widths, expected.widths)
    assert params.centres[-1] == pytest.approx(np.exp(-3.0))


def test_validate_reaches_dataclasses_inside_lists():
    from dataclasses import dataclass, field

    from drake_wbc.math.validation import positive, validate

    @dataclass
    class Item:
        size: float = 1.0

        def __post_init__(self):
            positive("size", self.size)

    @dataclass
    class Holder:
        items: list = field(default_factory=list)

    holder = Holder(items=[Item(), Item()])
    holder.items[1].size = -2.0
    with pytest.raises(ValueError, match=r"items\[1\]\.size = -2"):
        validate(holder)


def test_the_hardware_scenario_lists_every_hardware_option():
    """diagrams/hardware.yaml lists every HardwareOptions field at its
    default, as drake_wbc/hardware/README.md says."""
    from drake_wbc.experiments.scenario import find_scenario, load_scenario
    from drake_wbc.hardware.options import HardwareOptions

    path = find_scenario("hardware")
    assert_every_field_written(yaml_load_file(str(path))["hardware"],
                               HardwareOptions())
    assert load_scenario(path).hardware == HardwareOptions()
