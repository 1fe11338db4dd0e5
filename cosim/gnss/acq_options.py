"""The acquisition's command-line options, one spelling for every GNSS command (``gnss``,
``ins``, ``gnss-acquire``): ``--coherent-ms`` and ``--noncoherent`` (a fixed dwell of
``T`` ms x ``K`` sums, both or neither), ``--pfa`` (false-alarm probability of the whole
search) and, where the acquisition reads a flowing signal (``gnss``, ``ins``),
``--acq-limit-ms`` (the signal the search may consume). Derived from the fields of
:class:`~cosim.gnss.config.GnssRunConfig`, which check them."""
from __future__ import annotations

from ..core.receivers import Option
from .config import GnssRunConfig

__all__ = ["DWELL_OPTIONS", "ACQ_OPTIONS", "add_dwell_arguments"]

#: --coherent-ms, --noncoherent, --pfa.
DWELL_OPTIONS = (
    Option(GnssRunConfig, "acq_coherent_ms", flag="--coherent-ms", metavar="MS"),
    Option(GnssRunConfig, "acq_noncoherent", flag="--noncoherent", metavar="K"),
    Option(GnssRunConfig, "acq_pfa", flag="--pfa"),
)
#: The options of a run's acquisition (``gnss``, ``ins``).
ACQ_OPTIONS = DWELL_OPTIONS + (
    Option(GnssRunConfig, "acq_limit_ms", flag="--acq-limit-ms", metavar="MS"),
)


def add_dwell_arguments(parser) -> None:
    """Add :data:`DWELL_OPTIONS` to an ``argparse`` parser (``gnss-acquire``)."""
    for o in DWELL_OPTIONS:
        flags, kw = o.argparse_kwargs()
        parser.add_argument(*flags, **kw)
