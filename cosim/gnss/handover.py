"""Hand-over of acquired satellites to the channels of a GNSS channel array, as register
writes on its bus.

:func:`array_handover_writes` starts channel ``k`` of a
:class:`hdl.gnss.channel.GnssChannelArray` on satellite ``k`` of a list (PRN, Doppler, code
phase, e.g. from ``python -m cosim gnss-acquire``): for every channel its PRN, then the
writes of :func:`cosim.gnss.tracking.handover_writes` (carrier word of IF + Doppler, code
word of the chip rate + code Doppler, the slew that puts the prompt on the code phase).
The bus takes one write per cycle, so the channels' writes go out on consecutive cycles
from ``start_cycle``: ``4 * channels`` cycles, all before the first dump boundary (a code
period later), where every channel applies its own at once.
"""
from __future__ import annotations

from typing import NamedTuple

from dsp.gnss.ca_code import check_prn

__all__ = ["Satellite", "array_handover_writes"]


class Satellite(NamedTuple):
    """An acquired satellite: what a channel is handed over to."""

    prn: int
    doppler_hz: float           #: carrier Doppler, Hz
    code_phase_chips: float     #: received code phase at sample 0, chips


def array_handover_writes(p, sats, *, inverted: bool = False,
                          start_cycle: int = 0) -> list[tuple[int, int, int]]:
    """Bus writes ``(cycle, address, value)`` (address ``4 * channel + register``) that hand
    channel ``k`` over to ``sats[k]``.

    Parameters
    ----------
    p : GnssChannelParams
        The channels' parameters (real or complex input; the carrier word is
        ``carr_word(if_hz +- doppler)``, the sign turned when ``inverted``).
    sats : sequence of Satellite or (prn, doppler_hz, code_phase_chips)
        One per channel, channel 0 first.
    inverted : bool
        The Doppler sign is turned (a real recording with an inverted spectrum:
        :attr:`cosim.gnss.files.SampleFile.doppler_sign_inverted`; a complex one is read as
        ``I - jQ`` and needs no turn).
    start_cycle : int
        Cycle of the first write (>= 0).
    """
    from hdl.gnss.params import GnssChannelParams
    from .tracking import handover_writes
    if not isinstance(p, GnssChannelParams):
        raise ValueError(f"array hand-over needs a GnssChannelParams, not {p!r}")
    sats = [Satellite(*s) for s in sats]
    if not 1 <= len(sats) <= 64:
        raise ValueError(f"array hand-over needs 1 to 64 satellites (one per channel), not "
                         f"{len(sats)}")
    if isinstance(start_cycle, bool) or not isinstance(start_cycle, int) or start_cycle < 0:
        raise ValueError(f"start_cycle must be an integer >= 0, not {start_cycle!r}")
    regs = p.registers
    out, c = [], start_cycle
    for ch, s in enumerate(sats):
        check_prn(s.prn)
        writes = [(0, "prn", s.prn)] + handover_writes(p, float(s.doppler_hz),
                                                       float(s.code_phase_chips), inverted)
        for _, name, v in writes:
            out.append((c, 4 * ch + regs[name].address, int(v)))
            c += 1
    return out
