"""diagrams/milling_cell.log_signals: signals whose period is twice the
base period are logged by the base period's one logger
and read at their own instants, with the same times and values as a
logger of their own (the block pass logs its 4 ms signals with its 2 ms
ones: one Multiplexer and one VectorLogSink fewer, docs/results.md
section 5); a port that holds several signals is read once."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource, VectorLogSink
from pydrake.trajectories import PiecewisePolynomial

from robstiff_drake.diagrams.milling_cell import log_signals


def run(base_s, start_s):
    """{name: (times, samples)} of a 3-vector of time (t, t^2 and 1 - t) logged
    every 2 ms (first two), 4 ms and 8 ms (its parts), and the number of loggers."""
    b = DiagramBuilder()
    t = np.linspace(0.0, 1.0, 11)
    src = b.AddSystem(TrajectorySource(PiecewisePolynomial.FirstOrderHold(t, np.vstack([t, t ** 2, 1.0 - t]))))
    port = src.get_output_port()
    logs = log_signals(b, {"all": (port, 0.002), "first": (port, 0.002, slice(0, 1)),
                           "square": (port, 0.004, slice(1, 2)), "last": (port, 0.008, slice(2, 3))}, base_s=base_s)
    diagram = b.Build()
    sim = Simulator(diagram)
    sim.get_mutable_context().SetTime(start_s)
    sim.AdvanceTo(0.05)
    loggers = sum(isinstance(s, VectorLogSink) for s in diagram.GetSystems())
    return {name: log.read(sim.get_context()) for name, log in logs.items()}, loggers


@pytest.mark.parametrize("start_s", [0.0, 0.002, 0.006])
def test_a_slower_signal_in_the_base_logger_reads_as_its_own_logger(start_s):
    own, n_own = run(None, start_s)
    shared, n_shared = run(0.002, start_s)
    assert (n_own, n_shared) == (3, 2)  # (the 8 ms signal keeps its own: four times the base period)
    for name in own:
        assert np.array_equal(own[name][0], shared[name][0]), name
        assert np.array_equal(own[name][1], shared[name][1]), name
    t, x = shared["square"]
    assert np.allclose(np.diff(t), 0.004) and t[0] >= start_s and x.shape == (len(t), 1)
    assert np.array_equal(shared["first"][1][:, 0], shared["all"][1][:, 0])


def test_a_period_not_twice_the_base_keeps_its_own_logger():
    b = DiagramBuilder()
    src = b.AddSystem(TrajectorySource(PiecewisePolynomial.FirstOrderHold([0.0, 1.0], [[0.0, 1.0]])))
    logs = log_signals(b, {"a": (src.get_output_port(), 0.002), "b": (src.get_output_port(), 0.006)}, base_s=0.002)
    assert logs["a"].logger is not logs["b"].logger and logs["b"].stride == 1
