"""TACAN bearing DSP: reference decoding, the TACAN paper's 5-state Kalman filter, coarse/fine bearing."""
