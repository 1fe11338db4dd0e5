"""TACAN receiver co-simulation: the signal generator (:mod:`cosim.tacan.signal`) and the
end-to-end run (:mod:`cosim.tacan.run`, its configuration :mod:`cosim.tacan.config`, the
front-end backends :mod:`cosim.tacan.frontends`)."""
