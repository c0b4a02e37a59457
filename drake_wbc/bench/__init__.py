"""Benchmarks of drake_wbc, behind `drake-wbc bench`.

- distribution_race: the closed-form weighted distribution of eqs.
  (wbsln)/(wbccm) against Drake's DiffIK and QPs through qpsolvers, on
  the same seeded problems, after checking that they agree;
- control_tick: one tick of the controller Diagram, whole and per stage;
- scenarios: each scenario's real-time factor and peak memory, in a
  child process;
- timing: interleaved (round-robin) timing and its statistics;
- report: JSON and Markdown tables, the speed goals;
- profiling: cProfile of ticks and of a scenario;
- commands: `add_bench_arguments` and `run_bench`, the subcommand.

May import every layer up to the scenarios (drake_wbc.experiments); only
the command line imports it.
"""

from drake_wbc.bench.commands import add_bench_arguments, run_bench

__all__ = ["add_bench_arguments", "run_bench"]
