"""jaxnav.plot.figure_formats: PNG always, PDF/SVG beside it on request, unknown formats named."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import pytest

from jaxnav import plot


def _fig():
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    return fig


def test_png_only_by_default(tmp_path):
    out = plot.save_figure(_fig(), tmp_path / "a.png")
    assert out == tmp_path / "a.png"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png"]


def test_pdf_and_svg_beside_the_png(tmp_path):
    with plot.figure_formats("PDF", "svg", "png") as chosen:
        assert chosen == ("png", "pdf", "svg")
        plot.save_figure(_fig(), tmp_path / "b.png")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.pdf", "b.png", "b.svg"]
    assert (tmp_path / "b.pdf").read_bytes()[:5] == b"%PDF-"
    assert b"<svg" in (tmp_path / "b.svg").read_bytes()[:2000]
    plot.save_figure(_fig(), tmp_path / "c.png")  # the context is over: PNG only again
    assert not (tmp_path / "c.pdf").exists()


def test_unknown_format_is_named():
    with pytest.raises(ValueError, match="'jpeg'.*png, pdf, svg"):
        with plot.figure_formats("jpeg"):
            pass
