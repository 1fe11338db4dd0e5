"""Quantisation and bit-error studies (sweeps, word-length proposals, fault injection)."""
