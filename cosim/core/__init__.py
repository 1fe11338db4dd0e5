"""The generic co-simulation core: provenance and result files, input validation, the
receiver registry, the FPGA -> DSP link and DSP -> FPGA control path, the session interface
and the streaming pipeline. It imports no simulator backend, tool or receiver
(docs/explanation/architecture.md)."""
