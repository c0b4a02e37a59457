"""The run's log: SignalLogger's one sink against one LogVectorOutput a
signal, and RunLog's files."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    DiscreteTimeDelay,
    LogVectorOutput,
    Sine,
)

from drake_wbc.controller.run_log import RunLog, SignalLogger


def _signals(builder):
    """Named ports of a few sizes: a sine (3), its copy delayed by two
    updates of 3 ms (3, discrete, at another rate than the log's), a
    constant (1) and an empty constant (0)."""
    sine = builder.AddSystem(Sine([1.0, 2.0, 0.5], [3.0, 1.0, 7.0],
                                  [0.0, 0.3, 1.0], 3))
    delay = builder.AddSystem(DiscreteTimeDelay(0.003, 2, 3))
    builder.Connect(sine.get_output_port(0), delay.get_input_port())
    constant = builder.AddSystem(ConstantVectorSource([4.0]))
    empty = builder.AddSystem(ConstantVectorSource(np.zeros(0)))
    return {"sine": sine.get_output_port(0),
            "delayed": delay.get_output_port(),
            "alpha": constant.get_output_port(),
            "nothing": empty.get_output_port()}


def test_one_sink_logs_what_one_logger_a_signal_logs():
    builder = DiagramBuilder()
    ports = _signals(builder)
    log = SignalLogger(builder, ports, 0.01,
                       columns={"delayed": ("a", "b", "c")})
    alone = {name: LogVectorOutput(port, builder, 0.01)
             for name, port in ports.items() if port.size() > 0}
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.5)
    root = simulator.get_context()
    run = log.run_log(root, real_time_factor=3.0)
    assert list(run.signals) == ["sine", "delayed", "alpha"]
    assert "nothing" not in run
    assert run.real_time_factor == 3.0
    assert len(run.time) == 51
    for name, logger in alone.items():
        reference = logger.FindLog(root)
        np.testing.assert_array_equal(run.time, reference.sample_times())
        np.testing.assert_array_equal(run[name], reference.data().T)
    assert run.columns == {"sine": ("x0", "y0", "x1"),  # unnamed
                           "delayed": ("a", "b", "c"),  # named here
                           "alpha": ("alpha",)}  # named in run_log.SIGNALS


def test_a_log_without_signals_is_refused():
    builder = DiagramBuilder()
    ports = _signals(builder)
    with pytest.raises(ValueError, match="ports = .* at least one port"):
        SignalLogger(builder, {"nothing": ports["nothing"]}, 0.01)
    with pytest.raises(ValueError,
                       match=r"columns\['delayed'\] = .* have 3 names"):
        SignalLogger(builder, ports, 0.01, columns={"delayed": ("a",)})


def test_run_log_files_read_back(tmp_path):
    builder = DiagramBuilder()
    log = SignalLogger(builder, _signals(builder), 0.02)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(0.2)
    run = log.run_log(simulator.get_context())
    npz = run.save(tmp_path / "run")
    back = RunLog.load(npz)
    np.testing.assert_array_equal(back.time, run.time)
    assert back.columns == run.columns
    for name in run.signals:
        np.testing.assert_array_equal(back[name], run[name])
    table = np.loadtxt(tmp_path / "run.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(table[:, 0], run.time, rtol=1e-8)
    np.testing.assert_allclose(table[:, 1:4], run["sine"], rtol=1e-8,
                               atol=1e-12)
