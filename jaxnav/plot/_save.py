"""Saving figures: one call writes the PNG and any further formats chosen by the caller (PDF, SVG)."""

import contextlib
import contextvars
import pathlib

FORMATS = ("png", "pdf", "svg")
_extra = contextvars.ContextVar("jaxnav_figure_formats", default=())


@contextlib.contextmanager
def figure_formats(*formats: str):
    """Within the block, every figure jaxnav saves is also written in ``formats`` beside the PNG.

    ``formats``: any of "png", "pdf", "svg" (case-insensitive); "png" is always written, since
    the returned paths and the reports name the PNG. Example::

        with jaxnav.plot.figure_formats("pdf", "svg"):
            jaxnav.plot.plot_rtk(...)   # writes rtk.png, rtk.pdf, rtk.svg

    Raises:
      ValueError: an unknown format, naming it and the known ones.
    """
    wanted = []
    for f in formats:
        f = str(f).lower().lstrip(".")
        if f not in FORMATS:
            raise ValueError(f"unknown figure format {f!r}; choose from {', '.join(FORMATS)}")
        if f != "png" and f not in wanted:
            wanted.append(f)
    token = _extra.set(tuple(wanted))
    try:
        yield tuple(["png"] + wanted)
    finally:
        _extra.reset(token)


def save_figure(fig, path, *, dpi: int = 110) -> pathlib.Path:
    """Write ``fig`` to ``path`` (PNG, ``dpi``) and, inside :func:`figure_formats`, as PDF/SVG beside it.

    Returns the PNG path. Vector formats ignore ``dpi`` for lines and text.
    """
    path = pathlib.Path(path)
    fig.savefig(path, dpi=dpi)
    for f in _extra.get():
        fig.savefig(path.with_suffix("." + f))
    return path
