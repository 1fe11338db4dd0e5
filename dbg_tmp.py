import numpy as np
import tests.cosim.gnss.test_constellation as T
from tests.cosim.gnss.test_constellation import *
nav = read_rinex_nav(DATA / "brdc2800.15n")
sig = ConstellationSignal(config(nav, receiver=T._ins_receiver(), duration_s=20.0))
for s0 in (4.0, 10.0, 16.0):
  for h in (1e-3, 1e-4):
    s=np.array([s0])
    ph = [sig.truth_at(s + d).carrier_phase_cycles for d in (-h, h)]
    fd = (ph[1] - ph[0]) / (2 * h)
    print(s0, h, (fd - sig.truth_at(s).doppler_hz)[0,:4])
