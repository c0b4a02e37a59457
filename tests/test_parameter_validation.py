"""Every parameter dataclass rejects a bad or inconsistent value with a
message that names the field, its value and what is allowed; a scenario
file's error names the field's dotted path.

The parameter dataclasses (each checks its fields in __post_init__, and
drake_wbc.math.validation.validate runs the checks of a whole tree again):

- controller: ControllerParameters (drake_wbc.controller.parameters),
  ArmControllerParameters (arm_control), CapabilityBand,
  ArmCapabilityParameters (capability), WorkspaceAdapterParameters
  (workspace), MotionDistributorParameters (distribution),
  RobustCompensatorParameters (compensation), BaseFilterParameters
  (filtering), SingularityDamping (distribution), LocalWorkspace
  (workspace), DmpParameters (dmp),
  StiffnessCouplingParameters, AdmittanceCouplingParameters,
  WholeBodyCdmpParameters, RepulsiveFieldParameters, BaseCdmpParameters,
  ArmCdmpParameters (cdmp);
- station: StationOptions (station.simulation), BaseDriverParameters,
  ArmDriverParameters (station.drivers), ForceTorqueSensorParameters
  (station.force_torque), LidarParameters (station.lidar),
  CylinderObstacle, BoxObstacle, WalkingPerson, HandForce, Scene
  (station.scene);
- scenario: Schedule, TaskInputs, Variant, OutputOptions, Scenario
  (scenario).
"""

import math
import re

import numpy as np
import pytest

from drake_wbc.controller import ControllerParameters
from drake_wbc.controller.task import Schedule, TaskInputs
from drake_wbc.experiments.scenario import (
    OutputOptions,
    Scenario,
    Variant,
    load_scenario,
)
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.math.arm_control import ArmControllerParameters
from drake_wbc.math.capability import (
    ArmCapabilityParameters,
    CapabilityBand,
)
from drake_wbc.math.cdmp import (
    AdmittanceCouplingParameters,
    ArmCdmpParameters,
    BaseCdmpParameters,
    RepulsiveFieldParameters,
    StiffnessCouplingParameters,
    WholeBodyCdmpParameters,
)
from drake_wbc.math.compensation import RobustCompensatorParameters
from drake_wbc.math.distribution import (
    MotionDistributorParameters,
    SingularityDamping,
)
from drake_wbc.math.dmp import DmpParameters
from drake_wbc.math.filtering import BaseFilterParameters
from drake_wbc.math.validation import validate
from drake_wbc.math.workspace import (
    LocalWorkspace,
    WorkspaceAdapterParameters,
)
from drake_wbc.station.drivers import ArmDriverParameters, BaseDriverParameters
from drake_wbc.station.force_torque import ForceTorqueSensorParameters
from drake_wbc.station.lidar import LidarParameters
from drake_wbc.station.scene import (
    BoxObstacle,
    CylinderObstacle,
    HandForce,
    Scene,
    WalkingPerson,
)
from drake_wbc.station.simulation import StationOptions

NAN, INF = math.nan, math.inf

CASES = [
    # (dataclass, field overrides, fragments the message must hold: the
    # field's name with its value, then what is allowed)
    (CapabilityBand, dict(lower=0.04, upper=0.035),
     ["lower = 0.04", "upper = 0.035", "strictly below"]),
    (CapabilityBand, dict(lower=0.04, upper=0.04), ["lower = 0.04"]),
    (CapabilityBand, dict(lower=-0.01), ["lower = -0.01", "0 or greater"]),
    (CapabilityBand, dict(upper=NAN), ["upper = nan", "finite"]),
    (ArmCapabilityParameters, dict(joint_limit_gain=-1.0),
     ["joint_limit_gain = -1.0", "greater than 0"]),
    (ArmCapabilityParameters, dict(gradient_damping=INF),
     ["gradient_damping = inf", "finite"]),
    (ArmCapabilityParameters, dict(gradient_damping_threshold=0.0),
     ["gradient_damping_threshold = 0.0"]),
    (WorkspaceAdapterParameters, dict(mode="flying"),
     ["mode = 'flying'", "'intuitive-phri'"]),
    (WorkspaceAdapterParameters, dict(sigma_xy=1.5),
     ["sigma_xy = 1.5", "[0.0, 1.0]"]),
    (WorkspaceAdapterParameters, dict(sigma_phi=0.0),
     ["sigma_phi = 0.0", "(0, 1)"]),
    (WorkspaceAdapterParameters, dict(workspace=3),
     ["workspace = 3", "LocalWorkspace"]),
    (LocalWorkspace, dict(extent_lower=0.8, extent_upper=0.75),
     ["extent_lower = 0.8", "extent_upper = 0.75"]),
    (LocalWorkspace, dict(extent_lower=0.8, extent_upper=0.8),
     ["extent_lower = 0.8", "extent_upper = 0.8"]),
    (LocalWorkspace, dict(deflection_lower=0.7),
     ["deflection_lower = 0.7", "deflection_upper = 0.61"]),
    (LocalWorkspace, dict(deflection_upper=4.0),
     ["deflection_upper = 4.0", "3.14159"]),
    (LocalWorkspace, dict(extent_lower=-0.1), ["extent_lower = -0.1"]),
    (MotionDistributorParameters, dict(null_space_gain=-0.1),
     ["null_space_gain = -0.1", "0 or greater"]),
    (MotionDistributorParameters, dict(smooth_switch_off=1),
     ["smooth_switch_off = 1", "True or False"]),
    (MotionDistributorParameters, dict(damping="none"),
     ["damping = 'none'", "SingularityDamping or None"]),
    (SingularityDamping, dict(threshold=0.0), ["threshold = 0.0"]),
    (SingularityDamping, dict(threshold=1.0), ["threshold = 1.0", "(0, 1)"]),
    (SingularityDamping, dict(max_squared=-1e-4), ["max_squared = -0.0001"]),
    (RobustCompensatorParameters, dict(compensation_switch=1.5),
     ["compensation_switch = 1.5", "[0, 1]"]),
    (BaseFilterParameters, dict(zeta=0.0), ["zeta = 0.0", "greater than 0"]),
    (BaseFilterParameters, dict(zeta=-1.0), ["zeta = -1.0"]),
    (BaseFilterParameters, dict(omega_f=0.0), ["omega_f = 0.0"]),
    (BaseFilterParameters, dict(enabled="yes"), ["enabled = 'yes'"]),
    (DmpParameters, dict(alpha_z=0.0), ["alpha_z = 0.0"]),
    (DmpParameters, dict(beta_z=-1.0), ["beta_z = -1.0"]),
    (DmpParameters, dict(tau=NAN), ["tau = nan"]),
    (DmpParameters, dict(duration=-1.0), ["duration = -1.0"]),
    (DmpParameters, dict(num_basis=0), ["num_basis = 0", "1 or greater"]),
    (DmpParameters, dict(num_basis=2.5), ["num_basis = 2.5", "integer"]),
    (StiffnessCouplingParameters, dict(k_p=-1.0), ["k_p = -1.0"]),
    (StiffnessCouplingParameters, dict(dmp=None), ["dmp = None"]),
    (AdmittanceCouplingParameters, dict(D_a=0.0), ["D_a = 0.0"]),
    (AdmittanceCouplingParameters, dict(D_a=[[1.0, 2.0], [0.0, 1.0]]),
     ["D_a = ", "symmetric positive definite"]),
    (AdmittanceCouplingParameters, dict(D_a=np.eye(2), F_d=[1.0, 2.0, 3.0]),
     ["F_d = [1. 2. 3.] has shape (3,)", "(2,)"]),
    (WholeBodyCdmpParameters, dict(k_hri=-0.05), ["k_hri = -0.05"]),
    (RepulsiveFieldParameters, dict(k_obs=-0.01), ["k_obs = -0.01"]),
    (RepulsiveFieldParameters, dict(d_th=0.0), ["d_th = 0.0"]),
    (RepulsiveFieldParameters, dict(half_sizes=[0.4]),
     ["half_sizes = [0.4] has shape (1,)", "(2,)"]),
    (RepulsiveFieldParameters, dict(d_min=0.6),
     ["d_min = 0.6", "(0, d_th = 0.5)"]),
    (BaseCdmpParameters, dict(repulsion=None), ["repulsion = None"]),
    (ArmCdmpParameters, dict(S_m=(0.5, 1, 1, 1, 1, 1)),
     ["S_m = [0.5 1.  1.  1.  1.  1. ]", "S_m[0] = 0.5", "must be 0 or 1"]),
    (ArmCdmpParameters, dict(S_m=(1, 1, 1, 1, 1, 2)),
     ["S_m = ", "S_m[5] = 2.0", "must be 0 or 1"]),
    (ArmCdmpParameters, dict(S_m=(1, 1, 1, 1, 1, NAN)),
     ["S_m = ", "finite"]),
    (ArmCdmpParameters, dict(S_m=(0, 1, 1)),
     ["S_m = [0. 1. 1.] has shape (3,)"]),
    (ArmCdmpParameters, dict(F_d=[1.0, 2.0]), ["F_d = [1. 2.] has shape (2,)"]),
    (ArmCdmpParameters, dict(k_f=-0.01), ["k_f = -0.01"]),
    (BaseDriverParameters, dict(lag=0.0), ["lag = 0.0"]),
    (BaseDriverParameters, dict(velocity_limits=[1.0, 1.0, -1.0]),
     ["velocity_limits = [1.0, 1.0, -1.0]", "> 0"]),
    (BaseDriverParameters, dict(acceleration_limits=[1.0, 1.0]),
     ["acceleration_limits = [1. 1.] has shape (2,)"]),
    (BaseDriverParameters, dict(damping_ratio=2.0),
     ["damping_ratio = 2.0", "[0.001, 1.0]"]),
    (BaseDriverParameters, dict(servo_time_constant=0.15),
     ["servo_time_constant = 0.15", "lag = 0.2"]),
    (ArmDriverParameters, dict(damping_ratio=0.0), ["damping_ratio = 0.0"]),
    (ArmDriverParameters, dict(min_inertia=-0.2), ["min_inertia = -0.2"]),
    (ForceTorqueSensorParameters, dict(rate=0.0), ["rate = 0.0"]),
    (ForceTorqueSensorParameters, dict(force_noise_std=-0.1),
     ["force_noise_std = -0.1"]),
    (ForceTorqueSensorParameters, dict(torque_range=INF),
     ["torque_range = inf"]),
    # A resolution of the whole range was accepted: every reading within
    # it rounded to 0 (or to the range), a sensor that reads nothing.
    (ForceTorqueSensorParameters, dict(force_range=300.0,
                                       force_resolution=300.0),
     ["force_resolution = 300.0", "force_range = 300.0", "below the range"]),
    (ForceTorqueSensorParameters, dict(torque_range=30.0,
                                       torque_resolution=50.0),
     ["torque_resolution = 50.0", "torque_range = 30.0"]),
    (ForceTorqueSensorParameters, dict(seed=1.5),
     ["seed = 1.5", "whole number"]),
    (LidarParameters, dict(field_of_view=7.0), ["field_of_view = 7.0"]),
    (LidarParameters, dict(num_beams=0), ["num_beams = 0"]),
    (LidarParameters, dict(max_range=0.01),
     ["max_range = 0.01", "min_range = 0.05"]),
    (LidarParameters, dict(seed=True), ["seed = True"]),
    (StationOptions, dict(time_step=0.006), ["time_step = 0.006", "5 ms"]),
    (StationOptions, dict(initial_arm_positions=[0, 0, np.nan, 0, 0, 0]),
     ["initial_arm_positions", "nan"]),
    (StationOptions, dict(initial_base_pose=[0.0, 0.0]),
     ["initial_base_pose = [0. 0.] has shape (2,)"]),
    # A heading of 1e17 rad was accepted, and the base then could not
    # turn: 1e17 + w h rounds to 1e17 (odometry's yaw frozen while its
    # yaw rate said 0.4 rad/s).
    (StationOptions, dict(initial_base_pose=[0.0, 0.0, 1e17]),
     ["initial_base_pose[2] = 1e+17 rad", "within +-2 pi rad"]),
    (StationOptions, dict(base="fast"), ["base = 'fast'"]),
    (StationOptions, dict(time_step=0.0003),
     ["arm.command_period = 0.01", "time_step = 0.0003", "whole multiple"]),
    (StationOptions, dict(arm=ArmDriverParameters(command_period=0.0105)),
     ["arm.command_period = 0.0105", "time_step = 0.001", "whole multiple"]),
    (StationOptions, dict(arm=ArmDriverParameters(servo_frequency=600.0)),
     ["arm.servo_frequency = 600.0", "time_step = 0.001", "Nyquist",
      "500"]),
    # The drivers run at the plant's step, the one step there is: a
    # 5 ms loop at 0.2 ms was refused for the base's own default step of
    # 1 ms (a field the station then replaced by its own).
    (StationOptions, dict(time_step=0.0002, base=BaseDriverParameters(
        lag=0.005, servo_time_constant=0.001)), []),
    (StationOptions, dict(time_step=0.005, base=BaseDriverParameters(
        loop="jerky")),
     ["time_step = 0.005 s", "base.lag = 0.02 s", "lag / 10"]),
    (CylinderObstacle, dict(radius=-0.1), ["radius = -0.1"]),
    (BoxObstacle, dict(size=[1.0, 0.0, 1.0]), ["size[1] = 0.0"]),
    (WalkingPerson, dict(times=[0.0, 1.0], waypoints=[[0, 0]]),
     ["waypoints = [[0. 0.]] has shape (1, 2)", "(2, 2)"]),
    (HandForce, dict(times=[1.0, 0.5], forces=[[0, 0, 0]] * 2),
     ["times = [1.0, 0.5]", "strictly increasing"]),
    (Scene, dict(cylinders=[CylinderObstacle(name="a"),
                            CylinderObstacle(name="a")]),
     ["cylinders[1].name = 'a'", "unique"]),
    (Schedule, dict(times=[1.0, 0.0], values=[[0.0], [1.0]]),
     ["times = [1.0, 0.0]", "strictly increasing"]),
    (Schedule, dict(times=[0.0], values=[]), ["values has 0 entries"]),
    (Schedule, dict(times=[0.0], values=[[NAN]]), ["values[0] = ", "finite"]),
    (Schedule, dict(interpolation="cubic"), ["interpolation = 'cubic'"]),
    (TaskInputs, dict(phri_switch=Schedule(times=[0.0], values=[[0.5]])),
     ["phri_switch.values[0][0] = 0.5", "must be 0 or 1"]),
    (TaskInputs, dict(compensation_switch=Schedule(times=[0.0],
                                                   values=[[1.5]])),
     ["compensation_switch.values[0][0] = 1.5", "must lie in [0, 1]"]),
    (TaskInputs, dict(null_space_gain=Schedule(times=[0.0], values=[[-0.1]])),
     ["null_space_gain.values[0][0] = -0.1", "0 or greater"]),
    (TaskInputs, dict(reference_velocity=Schedule(times=[0.0],
                                                  values=[[0.1, 0.0]])),
     ["reference_velocity.values = ", "6 entries"]),
    (TaskInputs, dict(desired_wrench=None), []),  # None: the default
    (Variant, dict(name="a b"), ["name = 'a b'"]),
    (Variant, dict(base_filter="no"), ["base_filter = 'no'"]),
    (Variant, dict(label=3), ["label = 3", "string"]),
    (OutputOptions, dict(log_period=0.0), ["log_period = 0.0"]),
    (OutputOptions, dict(replay="yes"), ["replay = 'yes'"]),
    (Scenario, dict(experiment="dance"), ["experiment = 'dance'"]),
    (Scenario, dict(duration=0.0), ["duration = 0.0"]),
    (Scenario, dict(duration=NAN), ["duration = nan"]),
    (Scenario, dict(description=5), ["description = 5"]),
    (Scenario, dict(variants=[]), ["variants = []"]),
    (Scenario, dict(variants=[Variant(), Variant()]),
     ["variants = ['run', 'run']"]),
    (Scenario, dict(scene="empty"), ["scene = 'empty'"]),
    (Scenario, dict(controller=ControllerParameters(time_step=0.0105)),
     ["controller.time_step = 0.0105", "station.time_step = 0.001"]),
    (Scenario, dict(controller=ControllerParameters(time_step=0.005)),
     ["station.arm.command_period = 0.01", "controller.time_step = 0.005"]),
    (Scenario, dict(scene=Scene(cylinders=[CylinderObstacle(
        name="pillar", position=[0.45, 0.0], radius=0.1)])),
     ["scene.cylinders[0] ('pillar')", "initial_base_pose", "overlaps"]),
    (Scenario, dict(scene=Scene(boxes=[BoxObstacle(
        name="crate", center=[0.0, 0.5, 0.2], size=[0.3, 0.5, 0.4],
        yaw=0.3)])),
     ["scene.boxes[0] ('crate')", "overlaps"]),
    (Scenario, dict(hardware=HardwareOptions(publish_period=0.02)),
     ["hardware.publish_period = 0.02", "controller.time_step = 0.01"]),
    # ControllerParameters and ArmControllerParameters: their own checks.
    (ControllerParameters, dict(time_step=0.0), ["time_step = 0.0"]),
    (ControllerParameters, dict(time_step=0.02,
                                base_filter=BaseFilterParameters(
                                    omega_f=200.0)),
     ["time_step = 0.02", "base_filter.omega_f = 200.0", "Nyquist"]),
    (ControllerParameters, dict(time_step=0.01,
                                base_filter=BaseFilterParameters(
                                    omega_f=400.0)),
     ["base_filter.omega_f = 400.0", "time_step = 0.01", "Nyquist",
      "314.159"]),
    (ControllerParameters, dict(time_step=0.2,
                                base_filter=BaseFilterParameters(
                                    omega_f=20.0)),
     ["base_filter.omega_f = 20.0", "time_step = 0.2", "Nyquist"]),
    (ControllerParameters, dict(capability="x"), ["capability = 'x'"]),
    (ControllerParameters, dict(capability_band="narrow"),
     ["capability_band = 'narrow'", "CapabilityBand"]),
    (ControllerParameters, dict(phri_switch=0.5),
     ["phri_switch = 0.5", "0 or 1"]),
    (ControllerParameters, dict(phri_switch=2), ["phri_switch = 2"]),
    (RepulsiveFieldParameters, dict(max_force=-1.0), ["max_force = -1.0"]),
    (ArmControllerParameters, dict(damping=-0.05), ["damping = -0.05"]),
    (ArmControllerParameters, dict(lower=[-1.0] * 6),
     ["lower = [-1.0", "upper = None", "both limits or neither"]),
    (ArmControllerParameters, dict(lower=[1.0] * 6, upper=[-1.0] * 6),
     ["lower[0] = 1.0", "upper[0] = -1.0", "strictly below"]),
    (ArmControllerParameters, dict(velocity_limits=[1.57] * 5 + [0.0]),
     ["velocity_limits", "0.0"]),
    (ArmControllerParameters, dict(use_acceleration_limit="on"),
     ["use_acceleration_limit = 'on'"]),
]


def _id(case):
    kind, overrides, _ = case
    return f"{kind.__name__}-{'-'.join(overrides)}"


@pytest.mark.parametrize("case", CASES, ids=[_id(c) for c in CASES])
def test_a_bad_value_is_named_with_what_is_allowed(case):
    kind, overrides, fragments = case
    if not fragments:  # accepted (e.g. None for a default)
        validate(kind(**overrides))
        return
    with pytest.raises(ValueError) as error:
        kind(**overrides)
    message = str(error.value)
    for fragment in fragments:
        assert fragment in message, message
    assert "not allowed" in message


@pytest.mark.parametrize("case", [c for c in CASES if c[2]],
                         ids=[_id(c) for c in CASES if c[2]])
def test_validate_catches_a_bad_value_assigned_after_construction(case):
    """The checks run again on assignment through validate (as after
    yaml_load_typed), with the same message."""
    kind, overrides, fragments = case
    params = kind()
    for name, value in overrides.items():
        setattr(params, name, value)
    with pytest.raises(ValueError) as error:
        validate(params)
    for fragment in fragments:
        assert fragment in str(error.value), str(error.value)


YAML_CASES = [
    ("duration: -1", ["duration = -1", "greater than 0"]),
    ("controller: {arm_cdmp: {S_m: [0.5, 1, 1, 1, 1, 1]}}",
     ["controller.arm_cdmp.S_m = ", "controller.arm_cdmp.S_m[0] = 0.5",
      "0 or 1"]),
    ("controller: {phri_switch: 0.5}",
     ["controller.phri_switch = 0.5", "0 or 1"]),
    # One band and one default S_hri (ControllerParameters'
    # capability_band and phri_switch): the stages' former copies are
    # unknown keys.
    ("controller: {distributor: {band: {lower: 0.03, upper: 0.04}}}",
     ["unknown key 'controller.distributor.band'", "null_space_gain"]),
    ("controller: {whole_body_cdmp: {S_hri: 1.0}}",
     ["unknown key 'controller.whole_body_cdmp.S_hri'", "k_hri"]),
    ("controller: {base_filter: {zeta: 0}}",
     ["controller.base_filter.zeta = 0", "greater than 0"]),
    ("controller: {base_filter: {omega_f: 400}}",
     ["controller.base_filter.omega_f = 400", "Nyquist"]),
    ("controller: {capability_band: {lower: 0.05, upper: 0.04}}",
     ["controller.capability_band.lower = 0.05",
      "controller.capability_band.upper = 0.04"]),
    ("controller: {workspace: {workspace: {extent_lower: 0.9}}}",
     ["controller.workspace.workspace.extent_lower = 0.9",
      "controller.workspace.workspace.extent_upper = 0.8"]),
    ("controller: {workspace: {workspace: {deflection_lower: 0.7}}}",
     ["controller.workspace.workspace.deflection_lower = 0.7"]),
    ("controller: {distributor: {damping: {threshold: 2.0}}}",
     ["controller.distributor.damping.threshold = 2.0", "(0, 1)"]),
    ("controller: {base_cdmp: {repulsion: {k_obs: -1}}}",
     ["controller.base_cdmp.repulsion.k_obs = -1"]),
    ("controller: {time_step: 0.005}",
     ["station.arm.command_period = 0.01", "controller.time_step = 0.005"]),
    ("station: {initial_arm_positions: [0, 0, 3, 0, 0, 0]}",
     ["station.initial_arm_positions[2] = 3.0", "limits"]),
    ("station: {arm: {servo_frequency: 600}}",
     ["station.arm.servo_frequency = 600", "Nyquist"]),
    ("station: {base: {lag: 0.005, servo_time_constant: 0.001}}",
     ["station.time_step = 0.001", "station.base.lag = 0.005",
      "lag / 10"]),
    # The drivers' step is the station's alone.
    ("station: {base: {time_step: 0.0001}}",
     ["unknown key 'station.base.time_step'"]),
    ("station: {arm: {time_step: 0.0001}}",
     ["unknown key 'station.arm.time_step'"]),
    ("station: {base: {loop: ringing, lag: 0.1}}",
     ["station.base.lag = 0.1", "loop = 'ringing'"]),
    ("station: {base: {loop: wobbly}}",
     ["station.base.loop = 'wobbly'", "ringing"]),
    ("station: {time_step: 0.005, base: {loop: jerky}}",
     ["station.time_step = 0.005", "station.base.lag = 0.02"]),
    ("station: {suspension: {pitch_frequency: 30}}",
     ["station.suspension.pitch_frequency = 30"]),
    ("station: {suspension: {damping_ratio: 0}}",
     ["station.suspension.damping_ratio = 0"]),
    ("station: {lidar: {max_range: 0.01}}",
     ["station.lidar.max_range = 0.01"]),
    ("scene: {people: [{name: a, radius: -1}]}",
     ["scene.people[0].radius = -1"]),
    ("scene: {cylinders: [{name: a}, {name: a, position: [3, 3]}]}",
     ["scene.cylinders[1].name = 'a'", "unique"]),
    ("scene: {cylinders: [{name: p, position: [0.2, 0.0]}]}",
     ["scene.cylinders[0] ('p')", "overlaps"]),
    ("task: {phri_switch: {times: [0], values: [[0.5]]}}",
     ["task.phri_switch.values[0][0] = 0.5", "0 or 1"]),
    ("task: {compensation_switch: {times: [0], values: [[2]]}}",
     ["task.compensation_switch.values[0][0] = 2.0"]),
    ("outputs: {log_period: 0}", ["outputs.log_period = 0"]),
    ("variants: [{name: 'a b'}]", ["variants[0].name = 'a b'"]),
    ("controller: {capability: {joint_limit_gain: .nan}}",
     ["controller.capability.joint_limit_gain = nan", "finite"]),
]


@pytest.mark.parametrize("text, fragments", YAML_CASES,
                         ids=[t for t, _ in YAML_CASES])
def test_a_bad_scenario_file_names_the_dotted_field_path(text, fragments):
    with pytest.raises(ValueError) as error:
        load_scenario(text=text)
    message = str(error.value)
    for fragment in fragments:
        assert fragment in message, message


def test_the_defaults_and_the_shipped_scenarios_are_valid():
    from drake_wbc.experiments.scenario import scenario_files

    for kind in {case[0] for case in CASES}:
        validate(kind())
    for path in scenario_files():
        load_scenario(path)


@pytest.mark.parametrize("overrides, fragment", [
    (dict(velocity_limits=[1.57] * 5 + [2.0]),
     "arm_controller.velocity_limits[5] = 2.0 is not allowed: must be at "
     "most the arm's own 1.57"),
    (dict(lower=[-3.2] + [-1.0] * 5, upper=[1.0] * 6),
     "arm_controller.lower[0] = -3.2 is not allowed: must be at least"),
])
def test_the_arm_controller_may_not_widen_the_arms_limits(overrides,
                                                          fragment):
    from drake_wbc.controller import build_controller

    params = ControllerParameters(
        arm_controller=ArmControllerParameters(**overrides))
    with pytest.raises(ValueError) as error:
        build_controller(params)
    assert fragment in str(error.value)


def test_the_arms_start_is_checked_against_the_robot_of_the_station():
    """StationOptions does not know the robot; the station checks the
    start against the arm it builds (a scenario, where it is loaded)."""
    from drake_wbc.station.simulation import SimulatedStation
    with pytest.raises(ValueError, match=re.escape(
            "station.initial_arm_positions[2] = 3.0 rad is not allowed: "
            "must lie within the joint's limits [-2.61, 2.61] rad")):
        SimulatedStation(StationOptions(
            initial_arm_positions=[0, 0, 3.0, 0, 0, 0]))
    with pytest.raises(ValueError, match="has 6 joints, give one value"):
        SimulatedStation(StationOptions(initial_arm_positions=[0.0] * 7))
    # Before the suspension is sized at that start, too.
    from drake_wbc.robot.suspension import SuspensionParameters
    with pytest.raises(ValueError, match="has 6 joints, give one value"):
        SimulatedStation(StationOptions(initial_arm_positions=[0.0] * 7,
                                        suspension=SuspensionParameters()))
