"""Snapshot-level fast path: matched-filter outputs S_1..S_4 drawn directly, batched over
Monte Carlo trials.

Model (exact for the IF chain of ``cosim.monopulse.signal`` and ``dsp.monopulse.golden``
up to the ADC): with chips aligned to snapshots and the integrate-and-dump DDC, the
corrected matched-filter output of channel ``i`` in block ``k`` is::

    S_i = k_i [ A exp(j theta_c) mean_n h_i(n)  +  n_i ],   n_i ~ CN(0, 4 sigma^2 |g_i|^2 / (D N))

``k_i`` the correction (steering ``exp(j phi_i0)`` times calibration), ``h_i(n)`` the channel
response at snapshot ``n`` (the mean over the block's snapshots keeps a moving target's phase
smear), ``n_i`` independent across channels, blocks and trials (the snapshot noise is white
and circular because the DDC nulls the 2 IF image). ``sigma^2 = sigma_w^2 + Delta^2 / 12``:
the ADC's quantisation is taken as additive uniform noise (valid while the noise spans many
steps; clipping is not modelled -- the IF path counts it).
"""
from __future__ import annotations

import math

import numpy as np

from .array import N_CHANNELS
from .signal import (STREAM_FAST, MonopulseSignalConfig, block_truth, channel_snapshots,
                     steering_array)


def noise_variance(cfg: MonopulseSignalConfig) -> np.ndarray:
    """Per-channel variance of the matched-filter noise ``E|n_i|^2`` (4,), before ``k_i``."""
    s2 = cfg.sigma_w ** 2
    if cfg.adc_bits is not None:
        s2 += cfg.adc_step ** 2 / 12
    if cfg.snr_db is None and cfg.adc_bits is None:
        s2 = 0.0
    return 4 * s2 * np.abs(cfg.array.channel_gains) ** 2 / (cfg.decimation * cfg.snapshots)


def snapshot_snr(cfg: MonopulseSignalConfig) -> float:
    """Per-channel SNR per snapshot including the ADC's quantisation noise (unit gain,
    ``|AF| = 1``): ``1 / E|n|^2`` of one snapshot (``noise_variance`` times N)."""
    var = noise_variance(cfg)[0] / abs(cfg.array.channel_gains[0]) ** 2 * cfg.snapshots
    return math.inf if var == 0 else 1.0 / var


def mean_outputs(cfg: MonopulseSignalConfig, steering, first_block=0, n_blocks=1,
                 calibration=None):
    """Noise-free corrected S (K, 4), and the correction k (K, 4) used."""
    steering = steering_array(steering, n_blocks)
    su, sv, *_ = block_truth(cfg, first_block, n_blocks)
    h = channel_snapshots(cfg, steering, su, sv).mean(axis=1)  # (K, 4)
    k = cfg.array.steering_correction(steering[:, 0], steering[:, 1])
    if calibration is not None:
        k = k * np.asarray(calibration)
    return k * np.exp(1j * cfg.carrier_phase) * h, k


def matched_filter_outputs(cfg: MonopulseSignalConfig, steering, trials: int = 1,
                           first_block: int = 0, n_blocks: int = 1, calibration=None,
                           seed=None, noise_free: bool = False):
    """S (trials, K, 4): corrected matched-filter outputs of ``trials`` independent runs.

    ``seed`` None: ``SeedSequence(cfg.seed, spawn_key=(3,))``; ``noise_free`` drops the noise
    (also the ADC's quantisation noise) whatever ``cfg.snr_db``.
    """
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
        raise ValueError(f"trials must be an integer >= 1, not {trials!r}")
    mu, k = mean_outputs(cfg, steering, first_block, n_blocks, calibration)
    out = np.broadcast_to(mu, (trials,) + mu.shape).copy()
    if noise_free:
        return out
    var = noise_variance(cfg)
    if np.all(var == 0):
        return out
    ss = np.random.SeedSequence(cfg.seed, spawn_key=(STREAM_FAST,)) if seed is None \
        else np.random.SeedSequence(seed)
    rng = np.random.default_rng(ss)
    w = rng.standard_normal((trials, n_blocks, N_CHANNELS, 2)) @ np.array([1.0, 1j])
    return out + k * np.sqrt(var / 2) * w
