"""TACAN front end: the Amaranth top (:mod:`hdl.tacan.frontend`) and its parameters and
bit-exact model (:mod:`hdl.tacan.model`)."""
