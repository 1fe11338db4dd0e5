"""The integrity figures of a GPS receiver run: fix jumps and the navigation message's counts.

Fix jumps (:func:`fix_jumps`), over the valid fixes of :func:`cosim.gnss.gps_outputs.
fix_rows` in time order, with a bound ``B`` (default :data:`JUMP_BOUND_M`, 30 m: some ten
times the few metres of a fix at 45 dB-Hz, far below the kilometres a wrong TOW or a wrong
ephemeris gives):

* with a truth (rows carrying ``err_3d_m``): a fix whose 3-D error against the truth at its
  epoch exceeds ``B`` (``off_truth``), and a fix whose step from the previous fix differs
  from the truth's step by more than ``B`` (``steps``);
* without a truth: a fix whose step from the previous fix differs by more than ``B`` from
  the step the two fixes' mean Doppler velocity predicts (``steps``).

A fix is counted once (``count``) however many of the rules it breaks; ``t_s`` lists their
recording times.

Navigation counts (:func:`navigation_counts`), over the channels of the run: words that
failed parity (never used), subframes decoded (all ten words clean) and withheld (a word
failed, or the preamble or subframe ID is not the grid's), channels with a TOW,
ephemerides decoded and withheld (with the decoder's reasons).
"""
from __future__ import annotations

import numpy as np

from ..core.validate import check_float

__all__ = ["JUMP_BOUND_M", "fix_jumps", "navigation_counts"]

#: Default fix-jump bound (m).
JUMP_BOUND_M = 30.0


def _ecef_velocity(r) -> np.ndarray:
    import pymap3d
    return np.array(pymap3d.enu2uvw(r["vel_e_mps"], r["vel_n_mps"], r["vel_u_mps"],
                                    r["lat_deg"], r["lon_deg"]))


def fix_jumps(rows, bound_m: float = JUMP_BOUND_M) -> dict:
    """The fix jumps among ``rows`` (module doc): ``{"bound_m", "count", "off_truth",
    "steps", "t_s"}`` (``off_truth`` None without a truth)."""
    bound = check_float("--jump-bound-m", bound_m, 0.0, lo_open=True, unit="m")
    fixes = sorted((r for r in rows if str(r["status"]).startswith("fix")),
                   key=lambda r: r["t_s"])
    truth = bool(fixes) and "err_3d_m" in fixes[0]
    off = {i for i, r in enumerate(fixes) if truth and not float(r["err_3d_m"]) <= bound}
    steps = set()
    for i in range(1, len(fixes)):
        a, b = fixes[i - 1], fixes[i]
        pa = np.array([a["x_m"], a["y_m"], a["z_m"]], dtype=float)
        pb = np.array([b["x_m"], b["y_m"], b["z_m"]], dtype=float)
        if truth:
            want = np.array([b[k] - a[k] for k in ("truth_x_m", "truth_y_m", "truth_z_m")])
        else:
            want = 0.5 * (_ecef_velocity(a) + _ecef_velocity(b)) * (b["t_s"] - a["t_s"])
        if not np.linalg.norm(pb - pa - want) <= bound:
            steps.add(i)
    jumps = sorted(off | steps)
    return {"bound_m": bound, "count": len(jumps), "off_truth": len(off) if truth else None,
            "steps": len(steps), "t_s": [float(fixes[i]["t_s"]) for i in jumps]}


def navigation_counts(channels) -> dict:
    """The navigation message's counts over ``channels`` (the ``as_dict`` of
    :class:`cosim.gnss.navigation.ChannelNav`; module doc)."""
    chans = list(channels)
    withheld = {f"G{c['prn']:02d}": c["ephemeris_withheld"] for c in chans
                if c.get("ephemeris_withheld")}
    return {"parity_failures": int(sum(c["parity_failures"] for c in chans)),
            "subframes": int(sum(len(c["subframes"]) for c in chans)),
            "subframes_withheld": int(sum(c["subframes_withheld"] for c in chans)),
            "channels_with_tow": int(sum(c["tow_known_s"] is not None for c in chans)),
            "ephemerides_decoded": int(sum(bool(c["ephemeris_decoded"]) for c in chans)),
            "ephemerides_withheld": withheld}
