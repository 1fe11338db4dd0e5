"""GPS L1 C/A receiver: the standard's tables and the DSP side."""
