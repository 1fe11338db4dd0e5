"""GPS L1 C/A receiver HDL: the tracking channel (:mod:`hdl.gnss.channel`) and its
bit-exact model (:mod:`hdl.gnss.model`)."""
