"""TACAN front end: the Amaranth top (:mod:`hdl.tacan.frontend`), its parameters and word
lengths (:mod:`hdl.tacan.params`), bit-exact model (:mod:`hdl.tacan.model`), FIFO merge of
the two searches (:mod:`hdl.tacan.fifo_merge`) and pulse-peak search (:mod:`hdl.tacan.peak`,
:mod:`hdl.tacan.peak_model`)."""
