"""Helpers shared by the TACAN front-end tests (``test_tacan_frontend*.py``; imported as
``_tacan_fe_util``, this folder being on ``sys.path``, see ``conftest.py``): the default
parameters, the Verilator marker, and the pulse-pair and both-searches configurations."""
from __future__ import annotations

from dataclasses import replace

import pytest

from cosim.tacan.signal import TacanSignalConfig
from dsp.tacan.frontend import PAIR_DETECTOR, FrontendConfig, pair_detector
from dsp.tacan.peak_params import PeakParams
from hdl.tacan.params import TacanFrontendParams
from cosim.core.executables import find_executable

P = TacanFrontendParams()
HAVE_VERILATOR = find_executable("verilator") is not None
verilator = pytest.mark.skipif(not HAVE_VERILATOR, reason="verilator not on PATH")


def both_params(cic_rate: int = 4, checks: bool = True, **kw) -> TacanFrontendParams:
    """The front end with both searches (``config.pair_peak``, as ``--detector both``): the
    single-pulse search and the pair detector (:data:`PAIR_DETECTOR`, its pair checks on
    unless ``checks=False``) at the X-mode spacing. With ``cic_rate=2`` (decimation 2) a pulse
    word and a pair word meet in one cycle with a sample on every cycle (checks on) or with
    gaps; at decimation 4 only with gaps (see ``test_collisions_follow_the_latency_difference``
    in ``test_tacan_frontend_both.py``)."""
    sig = TacanSignalConfig()
    cfg = FrontendConfig.for_signal(sig, cic_rate=cic_rate, peak=PeakParams(ts_step=cic_rate))
    base = replace(PAIR_DETECTOR, ts_step=cfg.peak.ts_step)
    if not checks:
        base = replace(base, pair_balance=0, pair_spread=0)
    cfg = replace(cfg, pair_peak=pair_detector(sig.mode, cfg.env_rate_hz, base))
    return TacanFrontendParams(config=cfg, adc_bits=sig.adc_bits, **kw)


BOTH = both_params()
