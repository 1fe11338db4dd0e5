"""The simulator backends, each session beside its simulator: Amaranth simulation
(:mod:`cosim.backends.pysim`), Verilator (:mod:`cosim.backends.verilator`), the Verilog they
build from (:mod:`cosim.backends.verilog`); :mod:`cosim.backends.factory` opens a session by
backend name (docs/explanation/architecture.md)."""
