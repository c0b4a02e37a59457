"""The CDMP-WBC controller: one Drake Diagram of the stages.

- parameters: ControllerParameters and loading them from YAML.
- diagram: `build_controller`, the stages wired as one tick of the paper's
  Fig. "cdmp_wbc".
- task: the task's inputs over time (Schedule, TaskInputs) and
  `add_controller`, the controller and its task wired to a station.
- run_log: the signals a run logs (SIGNALS, SignalLogger) and RunLog.

May import the math layer, the robot and the stages; never the station or
the hardware, which both drive the very same diagram through
`add_controller` and log it in the same format.
"""

from drake_wbc.controller.diagram import build_controller
from drake_wbc.controller.parameters import (
    ControllerParameters,
    load_controller_parameters,
)

__all__ = [
    "ControllerParameters",
    "build_controller",
    "load_controller_parameters",
]
