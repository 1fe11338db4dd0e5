"""Generic tools over the registered receivers: benchmark dispatch and the generic
benchmarks, backend comparison, Verilog export and lint, synthesis (docs/explanation/architecture.md).
The study engines are :mod:`cosim.studies`."""
