"""GPS L1 C/A: signal generator, line-of-sight dynamics, oscillator, correlation fast path."""
