"""TACAN bearing DSP: reference decoding, the seed's 5-state Kalman filter, coarse/fine bearing."""
