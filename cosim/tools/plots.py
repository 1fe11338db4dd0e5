"""The one way the toolkit draws a figure into a file: matplotlib's ``pyplot`` on the
non-interactive ``Agg`` backend (:func:`pyplot`; imported when a figure is drawn, so that
nothing that only computes pays for matplotlib), and a finished figure laid out, written and
closed (:func:`save_figure`)."""
from __future__ import annotations

__all__ = ["pyplot", "save_figure"]


def pyplot():
    """``matplotlib.pyplot`` on the ``Agg`` backend (files only, no display)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_figure(fig, path, *, dpi: int = 110) -> str:
    """Lay ``fig`` out (``tight_layout``), write it to ``path`` at ``dpi`` and close it;
    returns ``str(path)``."""
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)
    return str(path)
