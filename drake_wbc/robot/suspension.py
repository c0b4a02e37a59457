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
initial pose and the flexible mount held; drake_wbc.robot.model.
suspension_gains, beside the plant it sizes them on):

    k = I w^2 + G,   c = 2 zeta w I,

with I the suspension's diagonal block of the plant's mass matrix and G
the destabilising gravity stiffness d tau_g / d theta of the raised mass,
from the plant by central differences (as for the mount,
drake_wbc.robot.model.mount_rocking_modes).

EST values (see the comment in models/mcr_base.sdf): a wheeled base on
pneumatic or polyurethane tyres or on a sprung mecanum bogie rocks at 3
to 6 Hz, lightly damped (zeta 0.05 to 0.15); the defaults are 4 Hz and
0.1, the pivot at the wheels' axles (0.076 m).

Horizontal compliance of the wheels on the floor (an option of the
suspension, SuspensionParameters.horizontal; none by default). The base's
driven planar joints (x, y, yaw) then move the wheels' rolled position on
the floor (their velocity servo turns the wheels), and the wheels' hubs,
with the suspension and the chassis on them, sit on three more
unactuated spring-damper joints in series: `suspension_x`,
`suspension_y` (prismatic, along the wheels' own x and y) and
`suspension_yaw` (revolute about z at the footprint's centre), the
tyres' (or the rollers') shear under the drive's force. Their values
come, as for roll and pitch, from the modes asked for with the wheels
held (the drive stiff) and the arm and the mount held:

    k = I w^2,   c = 2 zeta w I,

with I the joints' diagonal block of the mass matrix (for x and y the
mass of the whole robot on its wheels, for yaw its inertia about the
footprint's centre); gravity does no work along them. (The arm's centre of
mass ahead of the yaw axis couples y and yaw: at 8 Hz each, the coupled
modes are 7.3 and 8.9 Hz, drake_wbc.robot.model.horizontal_modes; x
stays alone.) In the station the drive is not held but servoed: its
velocity servo (d = (m + J) / servo_time_constant, 16.5 kN s/m at 10
ms) in series with the spring moves the x mode of 8 Hz, zeta 0.1 to
7.8 Hz, zeta 0.31 (two-mass model m = 145 kg, J = 20 kg). So that the drive
has an inertia of its own (the chassis is no longer rigidly on the
driven joints), the base's actuators get the reflected inertia of the
wheels and their motors (`drive_inertia`).

EST values (HorizontalCompliance): a 100 to 150 kg omnidirectional base
on four polyurethane or rubber-rollered mecanum wheels of 0.15 m, or on
pneumatic castors, has a shear (longitudinal and lateral) stiffness of
about 5e4 to 3e5 N/m a wheel (rubber tread or rollers of about 10 mm on
a contact patch of a few cm^2, shear modulus 1 to 20 MPa; castors and
pneumatic tyres at the soft end, the drive train's torsion, reflected to
the floor through the 0.076 m radius, several times stiffer and so not
the limit): with the 145 kg robot on four such wheels, sqrt(4 k / m) /
(2 pi) = 6 to 14 Hz. The default is 8 Hz (9.2e4 N/m a wheel), lightly
damped as rubber's hysteresis is (zeta 0.05 to 0.2; 0.1). The yaw mode
of the same tyres at the wheels' 0.36 m from the centre is 1.1 to 1.2
times the horizontal one (k rho^2 over the robot's 13 to 15 kg m^2
about z); by default it is taken equal to it (the tracking step is along
x and barely turns the base). The drive's reflected inertia (per axis:
four wheels of 0.007 kg m^2 and their motors' rotors, 1e-4 kg m^2
through a 1:15 gearbox, over r^2 = 0.0058 m^2) is about 20 kg for x and
y and 20 x 0.36^2, about 2.6 kg m^2, for yaw; the defaults are 20 kg
and 2.6 kg m^2 (EST).
"""

from dataclasses import dataclass
from typing import NamedTuple
from xml.etree import ElementTree

import numpy as np

from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    in_closed_range,
    non_negative,
)

SUSPENSION_JOINTS = ("suspension_roll", "suspension_pitch")
"""The suspension's spring-damper joints (unactuated), when it is built."""

YAW_JOINT = "base_yaw"
"""The shipped bases' joint the chassis hangs from; the suspension goes
below it (a robot's own is its description's base.joints[2])."""

WHEELS_BODY = "suspension_wheels"
"""The massless body of the wheels, turned by the yaw joint (with a
horizontal compliance: their hubs, on the tyres' springs)."""

HORIZONTAL_JOINTS = ("suspension_x", "suspension_y", "suspension_yaw")
"""The horizontal compliance's spring-damper joints (unactuated), when it
is built: the wheels' shear along their x and y and about z."""

CONTACT_BODY = "suspension_contact"
"""The massless body of the wheels' rolled position on the floor, turned
by the yaw joint, when the suspension has a horizontal compliance."""

MIN_FREQUENCY, MAX_FREQUENCY = 0.5, 20.0
"""Hz: the suspension's modes allowed (at 20 Hz the coarsest plant step,
5 ms, still gives ten steps a period)."""


@dataclass
class HorizontalCompliance:
    """The horizontal compliance of the wheels on the floor (a scenario's
    `station: suspension: horizontal:`; EST values in the module's
    docstring).

    Attributes:
        frequency: Hz, the mode along x and y with the wheels held (8,
            EST: 6 to 14 Hz).
        yaw_frequency: Hz, the mode about z; None (the default): the same
            as `frequency`.
        damping_ratio: of the three modes (0.1, EST), in [0.01, 1].
        drive_inertia: kg, the wheels' and motors' inertia reflected to
            the base's x and y drive (20, EST), in [1, 200].
        drive_yaw_inertia: kg m^2, the same for the yaw drive (2.6, EST),
            in [0.1, 50].
    """

    frequency: float = 8.0
    yaw_frequency: float | None = None
    damping_ratio: float = 0.1
    drive_inertia: float = 20.0
    drive_yaw_inertia: float = 2.6

    def __post_init__(self):
        in_closed_range("frequency", self.frequency, MIN_FREQUENCY,
                        MAX_FREQUENCY)
        if self.yaw_frequency is not None:
            in_closed_range("yaw_frequency", self.yaw_frequency,
                            MIN_FREQUENCY, MAX_FREQUENCY)
        in_closed_range("damping_ratio", self.damping_ratio, 0.01, 1.0)
        in_closed_range("drive_inertia", self.drive_inertia, 1.0, 200.0)
        in_closed_range("drive_yaw_inertia", self.drive_yaw_inertia, 0.1,
                        50.0)

    def frequencies(self):
        """(3,) Hz: the modes along x, y and about z."""
        yaw = (self.frequency if self.yaw_frequency is None
               else self.yaw_frequency)
        return np.array([self.frequency, self.frequency, yaw])


@dataclass
class SuspensionParameters:
    """The suspension's modes (a scenario's `station: suspension:`).

    Attributes:
        roll_frequency: Hz, the roll mode with the mount held (4, EST).
        pitch_frequency: Hz, the pitch mode (4, EST).
        damping_ratio: of both modes (0.1, EST), in [0.01, 1].
        pivot_height: m above the floor of the roll and pitch axes (the
            wheels' axles, 0.076 m), >= 0 and at most the robot's deck
            (its description's base.height, checked where the suspension
            is sized on it: drake_wbc.robot.model.suspension_gains).
        horizontal: None (the default: the wheels rigid on the floor) or
            the HorizontalCompliance of the wheels on the floor, in series
            with the driven planar joints.
    """

    roll_frequency: float = 4.0
    pitch_frequency: float = 4.0
    damping_ratio: float = 0.1
    pivot_height: float = 0.076
    horizontal: HorizontalCompliance | None = None

    def __post_init__(self):
        for name in ("roll_frequency", "pitch_frequency"):
            in_closed_range(name, getattr(self, name), MIN_FREQUENCY,
                            MAX_FREQUENCY)
        in_closed_range("damping_ratio", self.damping_ratio, 0.01, 1.0)
        non_negative("pivot_height", self.pivot_height)
        self.horizontal = checked_instance(
            "horizontal", self.horizontal, HorizontalCompliance,
            lambda: None)


class SuspensionGains(NamedTuple):
    """The suspension's joint values (see
    drake_wbc.robot.model.suspension_gains, which sizes them on the
    robot's plant).

    Attributes:
        stiffness: (2,) roll, pitch springs, N m/rad.
        damping: (2,) roll, pitch dampers, N m s/rad.
        pivot_height: m above the floor.
        horizontal_stiffness: None (no horizontal compliance) or (3,)
            the x, y (N/m) and yaw (N m/rad) springs.
        horizontal_damping: None or (3,) their dampers (N s/m, N m s/rad).
        drive_inertia: None or (3,) the reflected inertia of the base's
            x, y (kg) and yaw (kg m^2) drives, with the horizontal
            compliance.
    """

    stiffness: np.ndarray
    damping: np.ndarray
    pivot_height: float
    horizontal_stiffness: np.ndarray | None = None
    horizontal_damping: np.ndarray | None = None
    drive_inertia: np.ndarray | None = None

    @property
    def has_horizontal(self):
        """Whether the wheels are compliant on the floor."""
        return self.horizontal_stiffness is not None


def suspended_base_sdf(sdf_text, gains, yaw_joint=YAW_JOINT):
    """The base's SDFormat `sdf_text` (models/mcr_base.sdf) with the
    suspension of SuspensionGains `gains` between its yaw joint (named
    `yaw_joint` in the file) and the chassis: the yaw joint turns the
    massless wheels body, which carries
    the chassis (`base_link`) through `suspension_roll` and
    `suspension_pitch`, each with its spring and damper. With a
    horizontal compliance the yaw joint turns the massless contact body
    instead, which carries the wheels body through `suspension_x`,
    `suspension_y` and `suspension_yaw` (springs and dampers too). At
    zero deflections the chassis is where it was. (A joint with force
    elements cannot be removed from a MultibodyPlant once parsed, so the
    joints go into the text before it is.)"""
    stiffness = as_vector("stiffness", gains.stiffness, 2)
    damping = as_vector("damping", gains.damping, 2)
    root = ElementTree.fromstring(sdf_text)
    model = root.find("model")
    yaw = None if model is None else next(
        (j for j in model.findall("joint") if j.get("name") == yaw_joint),
        None)
    if yaw is None:
        raise ValueError(
            f"yaw_joint = {yaw_joint!r} is not allowed: the base's "
            "SDFormat has no <model> with a <joint> of that name (the "
            "suspension goes under the chassis, below its yaw joint)")
    chassis = yaw.find("child").text
    joint = ('<joint name="{name}" type="{kind}">'
             '<pose relative_to="{frame}"/>'
             "<parent>{parent}</parent><child>{child}</child>"
             "<axis><xyz>{axis}</xyz><limit><lower>{lower!r}</lower>"
             "<upper>{upper!r}</upper><effort>0</effort>"
             "<velocity>10</velocity>"
             "</limit><dynamics><damping>{c!r}</damping>"
             "<spring_reference>0</spring_reference>"
             "<spring_stiffness>{k!r}</spring_stiffness></dynamics>"
             "</axis></joint>")
    parts = []
    if gains.has_horizontal:
        yaw.find("child").text = CONTACT_BODY
        k_h = as_vector("horizontal_stiffness", gains.horizontal_stiffness,
                        3)
        c_h = as_vector("horizontal_damping", gains.horizontal_damping, 3)
        # The tyres' shear: +-5 cm (+-0.1 rad) far beyond any deflection
        # under the drive's force.
        links = (CONTACT_BODY, "suspension_x_link", "suspension_y_link",
                 WHEELS_BODY)
        parts.append(_massless_link(CONTACT_BODY))
        for i, (name, kind, axis, bound) in enumerate(zip(
                HORIZONTAL_JOINTS, ("prismatic", "prismatic", "revolute"),
                ("1 0 0", "0 1 0", "0 0 1"), (0.05, 0.05, 0.1),
                strict=True)):
            parts.append(joint.format(
                name=name, kind=kind, frame=links[i], parent=links[i],
                child=links[i + 1], axis=axis, lower=-bound, upper=bound,
                c=float(c_h[i]), k=float(k_h[i])))
            parts.append(_massless_link(links[i + 1],
                                        f'<pose relative_to="{name}"/>'))
    else:
        yaw.find("child").text = WHEELS_BODY
        parts.append(_massless_link(WHEELS_BODY))
    roll, pitch = SUSPENSION_JOINTS
    parts += [
        f'<frame name="suspension_pivot" attached_to="{WHEELS_BODY}">'
        f"<pose>0 0 {float(gains.pivot_height)!r} 0 0 0</pose></frame>",
        joint.format(name=roll, kind="revolute", frame="suspension_pivot",
                     parent=WHEELS_BODY, child="suspension_roll_link",
                     axis="1 0 0", lower=-0.1, upper=0.1,
                     c=float(damping[0]), k=float(stiffness[0])),
        _massless_link("suspension_roll_link",
                       f'<pose relative_to="{roll}"/>'),
        joint.format(name=pitch, kind="revolute",
                     frame="suspension_roll_link",
                     parent="suspension_roll_link", child=chassis,
                     axis="0 1 0", lower=-0.1, upper=0.1,
                     c=float(damping[1]), k=float(stiffness[1])),
    ]
    for part in parts:
        model.append(ElementTree.fromstring(part))
    return ElementTree.tostring(root, encoding="unicode")


def _massless_link(name, pose=""):
    return (f'<link name="{name}">{pose}<inertial><mass>0</mass><inertia>'
            "<ixx>0</ixx><iyy>0</iyy><izz>0</izz><ixy>0</ixy><ixz>0</ixz>"
            "<iyz>0</iyz></inertia></inertial></link>")
