"""The base's suspension: roll and pitch compliance between the wheels and
the chassis, as spring-damper joints of the MultibodyPlant.

The robot's files (models/mcr_base.sdf) carry the chassis rigidly on its
planar joints; a station built with a suspension (StationOptions.
suspension) inserts, between the base's yaw joint and the chassis
(`base_link`, T_b), a massless wheel frame and two unactuated revolute
joints, `suspension_roll` (about x) then `suspension_pitch` (about y),
through a pivot `pivot_height` above the floor, each with a linear
torsional spring and a viscous damper. Their values come from the modes
asked for (frequency and damping ratio, with the arm at the station's
initial pose and the flexible mount held):

    k = I w^2 + G,   c = 2 zeta w I,

with I the suspension's diagonal block of the plant's mass matrix and G
the destabilising gravity stiffness d tau_g / d theta of the raised mass,
from the plant by central differences (as for the mount,
drake_wbc.robot.model.mount_rocking_modes).

EST values (see the comment in models/mcr_base.sdf): a wheeled base on
pneumatic or polyurethane tyres or on a sprung mecanum bogie rocks at 3
to 6 Hz, lightly damped (zeta 0.05 to 0.15); the defaults are 4 Hz and
0.1, the pivot at the wheels' axles (0.076 m).
"""

from dataclasses import dataclass
from typing import NamedTuple
from xml.etree import ElementTree

import numpy as np

from drake_wbc.math.validation import as_vector, in_closed_range

SUSPENSION_JOINTS = ("suspension_roll", "suspension_pitch")
"""The suspension's spring-damper joints (unactuated), when it is built."""

YAW_JOINT = "base_yaw"
"""The base joint the chassis hangs from; the suspension goes below it."""

WHEELS_BODY = "suspension_wheels"
"""The massless body of the wheels, turned by the yaw joint."""

MIN_FREQUENCY, MAX_FREQUENCY = 0.5, 20.0
"""Hz: the suspension's modes allowed (at 20 Hz the coarsest plant step,
5 ms, still gives ten steps a period)."""


@dataclass
class SuspensionParameters:
    """The suspension's modes (a scenario's `station: suspension:`).

    Attributes:
        roll_frequency: Hz, the roll mode with the mount held (4, EST).
        pitch_frequency: Hz, the pitch mode (4, EST).
        damping_ratio: of both modes (0.1, EST), in [0.01, 1].
        pivot_height: m above the floor of the roll and pitch axes (the
            wheels' axles, 0.076 m), in [0, 0.3] (the deck).
    """

    roll_frequency: float = 4.0
    pitch_frequency: float = 4.0
    damping_ratio: float = 0.1
    pivot_height: float = 0.076

    def __post_init__(self):
        for name in ("roll_frequency", "pitch_frequency"):
            in_closed_range(name, getattr(self, name), MIN_FREQUENCY,
                            MAX_FREQUENCY)
        in_closed_range("damping_ratio", self.damping_ratio, 0.01, 1.0)
        in_closed_range("pivot_height", self.pivot_height, 0.0, 0.3)


class SuspensionGains(NamedTuple):
    """The suspension's joint values (see `suspension_gains`).

    Attributes:
        stiffness: (2,) roll, pitch springs, N m/rad.
        damping: (2,) roll, pitch dampers, N m s/rad.
        pivot_height: m above the floor.
    """

    stiffness: np.ndarray
    damping: np.ndarray
    pivot_height: float


def suspended_base_sdf(sdf_text, gains):
    """The base's SDFormat `sdf_text` (models/mcr_base.sdf) with the
    suspension of SuspensionGains `gains` between its yaw joint and the
    chassis: the yaw joint turns the massless wheels body, which carries
    the chassis (`base_link`) through `suspension_roll` and
    `suspension_pitch`, each with its spring and damper. At zero angles
    the chassis is where it was. (A joint with force elements cannot be
    removed from a MultibodyPlant once parsed, so the joints go into the
    text before it is.)"""
    stiffness = as_vector("stiffness", gains.stiffness, 2)
    damping = as_vector("damping", gains.damping, 2)
    root = ElementTree.fromstring(sdf_text)
    model = root.find("model")
    yaw = next(j for j in model.findall("joint")
               if j.get("name") == YAW_JOINT)
    chassis = yaw.find("child").text
    yaw.find("child").text = WHEELS_BODY
    joint = ('<joint name="{name}" type="revolute">'
             '<pose relative_to="{frame}"/>'
             "<parent>{parent}</parent><child>{child}</child>"
             "<axis><xyz>{axis}</xyz><limit><lower>-0.1</lower>"
             "<upper>0.1</upper><effort>0</effort><velocity>10</velocity>"
             "</limit><dynamics><damping>{c!r}</damping>"
             "<spring_reference>0</spring_reference>"
             "<spring_stiffness>{k!r}</spring_stiffness></dynamics>"
             "</axis></joint>")
    roll, pitch = SUSPENSION_JOINTS
    parts = [
        _massless_link(WHEELS_BODY),
        f'<frame name="suspension_pivot" attached_to="{WHEELS_BODY}">'
        f"<pose>0 0 {float(gains.pivot_height)!r} 0 0 0</pose></frame>",
        joint.format(name=roll, frame="suspension_pivot", parent=WHEELS_BODY,
                     child="suspension_roll_link", axis="1 0 0",
                     c=float(damping[0]), k=float(stiffness[0])),
        _massless_link("suspension_roll_link",
                       f'<pose relative_to="{roll}"/>'),
        joint.format(name=pitch, frame="suspension_roll_link",
                     parent="suspension_roll_link", child=chassis,
                     axis="0 1 0", c=float(damping[1]),
                     k=float(stiffness[1])),
    ]
    for part in parts:
        model.append(ElementTree.fromstring(part))
    return ElementTree.tostring(root, encoding="unicode")


def _massless_link(name, pose=""):
    return (f'<link name="{name}">{pose}<inertial><mass>0</mass><inertia>'
            "<ixx>0</ixx><iyy>0</iyy><izz>0</izz><ixy>0</ixy><ixz>0</ixz>"
            "<iyz>0</iyz></inertia></inertial></link>")


def suspension_gains(params, arm_positions):
    """The SuspensionGains that give SuspensionParameters `params`' modes
    with the arm at `arm_positions` (6,): k = I w^2 + G and c = 2 zeta w
    I per axis (the module's docstring), I and G from a plant of the robot
    with the suspension."""
    from drake_wbc.robot.model import suspension_block

    unsprung = SuspensionGains(np.zeros(2), np.zeros(2), params.pivot_height)
    inertia, gravity = suspension_block(unsprung, arm_positions)
    w = 2.0 * np.pi * np.array([params.roll_frequency,
                                params.pitch_frequency])
    return SuspensionGains(
        stiffness=inertia * w * w + gravity,
        damping=2.0 * params.damping_ratio * w * inertia,
        pivot_height=params.pivot_height)
