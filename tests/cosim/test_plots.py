"""The one way figures are written (:mod:`cosim.tools.plots`): a PNG at the path asked, the
figure closed; the GNSS track report's figures through it."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from cosim.gnss.track_report import write_plots
from cosim.tools.plots import pyplot, save_figure

PNG = b"\x89PNG\r\n\x1a\n"


def test_save_figure_writes_a_png_and_closes_the_figure(tmp_path):
    plt = pyplot()
    before = set(plt.get_fignums())
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1], [1, 0])
    path = save_figure(fig, tmp_path / "f.png", dpi=50)
    assert path == str(tmp_path / "f.png")
    assert (tmp_path / "f.png").read_bytes()[:8] == PNG
    assert set(plt.get_fignums()) == before
    assert plt.get_backend().lower() == "agg"


def test_the_track_report_figures_are_written(tmp_path):
    t = np.linspace(0, 1, 20)
    asg = [SimpleNamespace(prn=p, channel=k, t=list(t), doppler=list(100 * t + p),
                           win_t=[0.5, 1.0], win_cn0=[40.0, 41.0], ip=list(np.cos(t)),
                           qp=list(np.sin(t))) for k, p in enumerate((3, 7))]
    paths = write_plots(SimpleNamespace(assignments=asg), tmp_path / "out")
    assert [p.rsplit("/", 1)[1] for p in paths] == ["doppler.png", "cn0.png", "prompt_iq.png"]
    for p in paths:
        with open(p, "rb") as f:
            assert f.read(8) == PNG
