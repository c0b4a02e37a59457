"""Motion modes and the weighting factors of the fixed ones (paper
Sec. IV-C).

The weighting factors sigma_xy, sigma_phi of eq. (weight-factors) select a
motion mode, Table (T:motion-mode):

    locomotion         sigma_xy = sigma_phi = 0        (base only)
    manipulation       sigma_xy = sigma_phi = 1        (arm only)
    loco-manipulation  0 < sigma_xy, sigma_phi < 1     (fixed, both)
    intuitive pHRI     sigma_xy,phi = f_xy,phi(q_a)    (adaptive)

`fixed_weighting_factors` gives the factors of the three fixed modes; those
of the intuitive pHRI mode adapt to the arm's configuration
(drake_wbc.math.workspace.local_workspace_state).
"""

import enum

from drake_wbc.math.validation import in_closed_range


class MotionMode(enum.StrEnum):
    """The motion modes of Table (T:motion-mode).

    A str enum: each member is also its name as a string (e.g.
    MotionMode.INTUITIVE_PHRI == "intuitive-phri"), which is how YAML
    files and WorkspaceAdapterParameters.mode carry it.
    """

    LOCOMOTION = "locomotion"
    MANIPULATION = "manipulation"
    LOCO_MANIPULATION = "loco-manipulation"
    INTUITIVE_PHRI = "intuitive-phri"

    @classmethod
    def parse(cls, mode):
        """Returns `mode` (a MotionMode or one of its names) as MotionMode.

        Raises:
            ValueError: naming `mode` and the allowed names.
        """
        if isinstance(mode, cls):
            return mode
        for member in cls:
            if mode == member.value:
                return member
        names = ", ".join(repr(m.value) for m in cls)
        raise ValueError(
            f"mode = {mode!r} is not allowed: must be a MotionMode or one "
            f"of {names}"
        )


def fixed_weighting_factors(mode, sigma_xy=0.5, sigma_phi=0.5):
    """(sigma_xy, sigma_phi) of the three fixed modes of Table
    (T:motion-mode): (0, 0) locomotion, (1, 1) manipulation, the given
    values (each in (0, 1)) loco-manipulation.

    Raises:
        ValueError: for the intuitive pHRI mode (see
            local_workspace_state), an unknown mode, or sigma outside
            (0, 1) in loco-manipulation.
    """
    mode = MotionMode.parse(mode)
    if mode is MotionMode.LOCOMOTION:
        return 0.0, 0.0
    if mode is MotionMode.MANIPULATION:
        return 1.0, 1.0
    if mode is MotionMode.LOCO_MANIPULATION:
        return (_open_unit("sigma_xy", sigma_xy),
                _open_unit("sigma_phi", sigma_phi))
    raise ValueError(
        f"mode = {mode.value!r} is not allowed here: its weighting factors "
        "are adaptive (local_workspace_state)"
    )


def _open_unit(name, value):
    number = in_closed_range(name, value, 0.0, 1.0)
    if number in (0.0, 1.0):
        raise ValueError(
            f"{name} = {number!r} is not allowed in loco-manipulation: must "
            "lie in (0, 1) (0 is locomotion, 1 manipulation)"
        )
    return number
