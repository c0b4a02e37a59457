"""The log of a run: the signals logged, sampled together, and the RunLog
they make.

The same format for a simulated run (drake_wbc.experiments.runner), a
deployment's loopback (drake_wbc.deployment.loopback) and a log of
lcm-logger read back (drake_wbc.deployment.lcm_logs), so that the
experiments' metrics and figures apply to each; and the times a run
advances to (`advance_times`), so that each log ends at its run's end.
"""

import itertools
import math

import numpy as np
from pydrake.systems.primitives import LogVectorOutput, Multiplexer

from drake_wbc.math.safety import STATUS_FIELDS
from drake_wbc.math.validation import non_negative, positive

SIGNALS = {
    # station: what the robot's sensors report
    "base.state_estimated": ("x", "y", "yaw", "vx", "vy", "wz"),
    "arm.position_measured": "q",  # q1, ..., qn: one a joint
    "wrist.wrench_measured": ("fx", "fy", "fz", "tx", "ty", "tz"),
    # station: ground truth, for metrics
    "truth.end_effector_pose": ("x", "y", "z", "roll", "pitch", "yaw"),
    "truth.end_effector_velocity": ("vx", "vy", "vz", "wx", "wy", "wz"),
    "truth.base_pose": ("x", "y", "yaw"),
    "truth.base_loop_velocity": ("vx", "vy", "wz"),
    "truth.mount_angles": ("roll", "pitch"),
    "truth.wrist_wrench": ("fx", "fy", "fz", "tx", "ty", "tz"),
    "truth.hand_force": ("fx", "fy", "fz", "tx", "ty", "tz"),
    "truth.people_positions": None,  # x0, y0, x1, y1, ...
    # controller: commands and diagnostics
    "base.velocity_command": ("vx", "vy", "wz"),
    "arm.position_command": "q",
    "capability": ("C_m",),
    "alpha": ("alpha",),
    "sigma_xy": ("sigma_xy",),
    "sigma_phi": ("sigma_phi",),
    "end_effector_deviation": ("vx", "vy", "vz", "wx", "wy", "wz"),
    "base_velocity": ("vx", "vy", "wz"),
    "filtered_base_velocity": ("vx", "vy", "wz"),
    "arm_velocity_command": ("vx", "vy", "vz", "wx", "wy", "wz"),
    "arm_limited": ("limited",),
    "base_saturation": ("limited", "velocity_scale", "acceleration_scale"),
    "safety_status": STATUS_FIELDS,
    # task
    "reference_velocity": ("vx", "vy", "vz", "wx", "wy", "wz"),
}
"""The logged signals and the names of their columns: a tuple of names,
a prefix numbered from 1 for one column an entry (the arm's joints, as
many as the robot has), or None (x0, y0, x1, ...). See `column_names`."""

OTHER_ROBOTS = {"truth.mount_angles": "passive"}
"""The names of the signals whose size is the robot's where it is not
their SIGNALS names' (a prefix numbered from 1): the base's passive
joints, in its description's order, of a robot whose are not the
shipped mount's roll and pitch."""


def column_names(name, size, columns=None):
    """The names of the `size` columns of signal `name`.

    Args:
        name: the signal's name.
        size: the number of entries of its vector.
        columns: dict signal name -> names (a tuple of names or a
            prefix, as in SIGNALS) for signals that SIGNALS does not name
            or that are to be named otherwise; None for none.

    Returns:
        tuple of `size` names: columns[name], else SIGNALS[name] (or
        OTHER_ROBOTS[name] where SIGNALS' are not `size`); a prefix p
        gives p1, ..., p<size>; x0, y0, x1, ... where neither names the
        signal.

    Raises:
        ValueError: when the names given for the signal are not one per
            entry.
    """
    given = (columns or {}).get(name)
    names = given or SIGNALS.get(name)
    if not given and name in OTHER_ROBOTS and len(names) != size:
        names = OTHER_ROBOTS[name]
    if isinstance(names, str):
        return tuple(f"{names}{i}" for i in range(1, size + 1))
    if names is None:
        return tuple(f"{'xy'[i % 2]}{i // 2}" for i in range(size))
    if len(names) != size:
        where = "columns" if given else "SIGNALS"
        raise ValueError(
            f"{where}[{name!r}] = {names!r} is not allowed: must have "
            f"{size} names, one per entry of the signal")
    return tuple(names)


def advance_times(duration, chunk):
    """The times a run of `duration` s advances its Simulator to,
    `chunk` s at a time: k chunk for k = 1, 2, ... and `duration` itself
    last, one at a time (a day's deployment in 0.05 s chunks is 1.7
    million of them). Each is computed, not summed: a sum of 200 chunks
    of 0.235 s ends 8.5e-14 s short of 47 s, and the log's periodic
    sample at the run's end with it.

    Raises:
        ValueError: unless duration >= 0 and chunk > 0, both finite
            (when called, before the first time).
    """
    duration = non_negative("duration", duration)
    chunk = positive("chunk", chunk)
    count = max(1, math.ceil(duration / chunk - 1e-9))
    return itertools.chain((k * chunk for k in range(1, count)),
                           (duration,))


class SignalLogger:
    """Named signals of a Diagram sampled together by one VectorLogSink.

    The ports are stacked by a Multiplexer into a single
    LogVectorOutput: one periodic publish a sample for all of them
    instead of one per signal (two dozen sinks cost a closed-loop run
    about 7% of its time). `run_log` splits the stack again by name.

    Args:
        builder: the DiagramBuilder holding the ports' systems.
        ports: dict signal name -> vector OutputPort, in logging order
            (ports of size 0 are left out).
        period: the sample period in s.
        columns: dict signal name -> column names (a tuple, or a prefix
            numbered from 1), for the signals that SIGNALS does not name
            (`column_names`).
    """

    def __init__(self, builder, ports, period, columns=None):
        given = list(ports)
        ports = {name: port for name, port in ports.items()
                 if port.size() > 0}
        if not ports:
            raise ValueError(f"ports = {given!r} is not allowed: must "
                             "name at least one port of size > 0")
        sizes = [port.size() for port in ports.values()]
        mux = builder.AddNamedSystem("log.signals", Multiplexer(sizes))
        for i, port in enumerate(ports.values()):
            builder.Connect(port, mux.get_input_port(i))
        self.sink = LogVectorOutput(mux.get_output_port(), builder, period)
        self.sink.set_name("log.sink")
        ends = np.cumsum([0] + sizes)
        self.slices = {name: slice(int(a), int(b)) for name, a, b in
                       zip(ports, ends[:-1], ends[1:], strict=True)}
        self.columns = {
            name: column_names(name, port.size(), columns)
            for name, port in ports.items()}

    def run_log(self, root_context, real_time_factor=np.nan,
                arm_fault=None):
        """The RunLog of the samples taken in `root_context` (and the
        run's `arm_fault`, see RunLog)."""
        log = self.sink.FindLog(root_context)
        data = log.data().T
        n = min(len(log.sample_times()), len(data))
        signals = {name: data[:n, part].copy()
                   for name, part in self.slices.items()}
        return RunLog(np.asarray(log.sample_times()[:n]), signals,
                      dict(self.columns), real_time_factor, arm_fault)


class RunLog:
    """The signals of one run: `log[name]` is an (N, k) array sampled at
    `log.time` (N,); `log.columns[name]` names its k columns.

    Attributes:
        time: (N,) sample times in s.
        signals: dict name -> (N, k) array.
        columns: dict name -> tuple of column names.
        real_time_factor: simulated over wall-clock time of the run.
        arm_fault: what the simulated station said of its arm in the
            run: its fault in one sentence (drake_wbc.station.
            arm_supervisor), or "none"; None where it is not known (a log
            of the robot's LCM streams, or one written before).
    """

    def __init__(self, time, signals, columns, real_time_factor=np.nan,
                 arm_fault=None):
        self.time, self.signals, self.columns = time, signals, columns
        self.real_time_factor = real_time_factor
        self.arm_fault = arm_fault

    def __getitem__(self, name):
        return self.signals[name]

    def __contains__(self, name):
        return name in self.signals

    def save(self, path):
        """Writes the log as NPZ (arrays `time` and one per signal, and
        `header`, a JSON description of the columns and units, the
        real-time factor and the arm's fault, each null if unknown) and
        as CSV next to it (one column per signal's
        component)."""
        import json

        factor = float(self.real_time_factor)
        header = json.dumps({
            "time": "s",
            "signals": {k: list(v) for k, v in self.columns.items()},
            "units": "SI: m, rad, s, N, N m; twists [v; w]; see "
                     "drake_wbc.controller.run_log.SIGNALS",
            "real_time_factor": None if np.isnan(factor) else factor,
            "arm_fault": self.arm_fault,
        })
        np.savez_compressed(path.with_suffix(".npz"), time=self.time,
                            header=header, **self.signals)
        names = ["time"] + [f"{k}.{c}" for k, cols in self.columns.items()
                            for c in cols]
        table = np.column_stack([self.time] + list(self.signals.values()))
        np.savetxt(path.with_suffix(".csv"), table, delimiter=",",
                   header=",".join(names), comments="", fmt="%.9g")
        return path.with_suffix(".npz")

    @classmethod
    def load(cls, path):
        """Reads a log written by `save` (the .npz file); its real-time
        factor is NaN if the log does not know it, its arm_fault None."""
        import json

        with np.load(path) as data:
            header = json.loads(str(data["header"]))
            signals = {k: data[k] for k in header["signals"]}
            columns = {k: tuple(v) for k, v in header["signals"].items()}
            factor = header.get("real_time_factor")
            return cls(data["time"], signals, columns,
                       np.nan if factor is None else factor,
                       header.get("arm_fault"))
