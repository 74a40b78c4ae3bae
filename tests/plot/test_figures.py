"""The publication figures on tiny synthetic inputs: each test asserts what its figure promises
(labels match curves, legends outside the data, the real statistic, spread bars, no lines joining
independent points or periods, readable ticks, the loss itself, titles naming the data and the seed,
one legend entry per kind of curve, unwrapped heading, whole-number counts)."""

import os
import pathlib
import types

import matplotlib

matplotlib.use("Agg")
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.container import ErrorbarContainer

import jaxnav.experiments.figures as _experiment_figures
import jaxnav.plot._ins as _ins
import jaxnav.plot._tune as _tune
from jaxnav import plot

# JAXNAV_KEEP_FIGURES=DIR keeps the PNGs for a look
KEEP = os.environ.get("JAXNAV_KEEP_FIGURES")


def _out(tmp_path, name):
    d = pathlib.Path(KEEP) if KEEP else tmp_path
    d.mkdir(parents=True, exist_ok=True)
    return d / name


@pytest.fixture
def captured(monkeypatch):
    """Figures saved by the functions that return paths (plot_s0, plot_sweep, plot_tune, plot_ins_*), by name;
    not rendered to files (time) unless JAXNAV_KEEP_FIGURES is set."""
    figs = {}

    def keep(save):
        def wrapper(fig, path, **kw):
            figs[pathlib.Path(path).name] = fig
            return save(fig, path, **kw) if KEEP else pathlib.Path(path)

        return wrapper

    for mod in (_experiment_figures, _tune, _ins):
        monkeypatch.setattr(mod, "save_figure", keep(mod.save_figure))
    return figs


def _data_lines(ax):
    """Lines that carry data (more than one point or a marker), excluding axhline/axvline helpers."""
    return [ln for ln in ax.get_lines() if len(np.atleast_1d(ln.get_xdata())) > 0]


def _legend_texts(ax):
    leg = ax.get_legend()
    return [] if leg is None else [t.get_text() for t in leg.get_texts()]


def _renderer(fig):
    """An Agg renderer for ``fig`` (the plot functions close their figures, which drops the canvas)."""
    if not hasattr(fig.canvas, "get_renderer"):
        FigureCanvasAgg(fig)
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _outside_right(legend, ax, r):
    """The legend starts right of the axes (it covers no data)."""
    return legend.get_window_extent(r).x0 >= ax.get_window_extent(r).x1 - 1


def test_filter_family_every_curve_and_band_labelled(tmp_path):
    T = 200
    rng = np.random.default_rng(0)
    t = np.arange(T, dtype=float)
    runs = {
        name: {"err": rng.normal(0, 3e-3, (T, 3)), "factors": 1 + rng.random(T), "q": rng.random((T, 3)) * 1e-9}
        for name in ("classic", "attenuated", "fading", "variance_compensation")
    }
    fig = _experiment_figures.plot_filter_family(runs, t, (80, 100), _out(tmp_path, "filter_family.png"), b=0.254)
    r = _renderer(fig)
    for ax in fig.axes:
        texts = _legend_texts(ax)
        for ln in _data_lines(ax):
            assert not ln.get_label().startswith("_"), f"unlabelled curve in {ax.get_ylabel()!r}"
            assert ln.get_label() in texts
        # the shaded band has its own entry; the band is never called "x"
        assert texts[0] == "unmodelled acceleration burst"
        assert _outside_right(ax.get_legend(), ax, r)  # beside the axes, not over the curves
    vc = fig.axes[3]
    assert _legend_texts(vc)[1:] == ["x (horizontal)", "y (horizontal)", "h (up)"]
    assert len(_data_lines(vc)) == 3
    f = fig.axes[2]
    styles = {ln.get_label(): ln.get_linestyle() for ln in _data_lines(f)}
    assert len(styles) == 2 and len(set(styles.values())) == 2  # S_k and lambda_k distinguishable


def test_stop_detection_plots_the_statistic_with_its_threshold(tmp_path):
    t = np.linspace(0.0, 100.0, 2001)
    moving = (t > 20) & (t < 60) | (t > 75) & (t < 95)
    stat = np.where(moving, 1e4, 1.0) * (1 + 0.1 * np.sin(t))
    spans = np.array([[0.0, 20.0], [60.0, 75.0], [95.0, 100.0]])
    fig = plot.plot_stop_detection(
        _out(tmp_path, "cadastral_detection_test.png"), t, stat, 10.0, spans, spans, title="synthetic"
    )
    ax = fig.axes[0]
    (curve,) = [ln for ln in ax.get_lines() if ln.get_label() == "GLRT statistic T_k"]
    np.testing.assert_allclose(curve.get_ydata(), stat)  # the statistic itself, not a 0/1 mask
    assert len(np.unique(curve.get_ydata())) > 2
    (thr,) = [ln for ln in ax.get_lines() if ln.get_label().startswith("threshold")]
    assert np.all(np.asarray(thr.get_ydata()) == 10.0)
    assert ax.get_yscale() == "log"  # spans four decades
    texts = _legend_texts(ax)
    assert {"detected stop", "true stop"} <= set(texts)
    # legend outside the data: the last stop (95-100 s, at the right edge) is not under it
    assert _outside_right(ax.get_legend(), ax, _renderer(fig))
    with pytest.raises(ValueError, match=r"\(2001,\).*\(3,\)"):
        plot.plot_stop_detection(tmp_path / "bad.png", t, stat[:3], 10.0, spans)


def test_stop_detection_linear_axis_and_second_trace(tmp_path):
    t = np.linspace(0.0, 10.0, 101)
    stat = 5.0 + np.cos(t)
    fig = plot.plot_stop_detection(
        tmp_path / "d.png", t, stat, 5.0, np.zeros((0, 2)), extra=(t, np.abs(np.sin(t)), "speed, m/s")
    )
    ax = fig.axes[0]
    assert ax.get_yscale() == "linear"
    assert "speed, m/s" in _legend_texts(ax)  # the twin axis' trace is in the one legend


def _truth(n=300):
    lat0, lon0 = np.deg2rad(39.0), np.deg2rad(108.0)
    s = np.linspace(0, 1, n)
    pos = np.stack([lat0 + 1e-4 * s, lon0 + 1e-4 * s, 100.0 + 5 * s], -1)
    return types.SimpleNamespace(pos=pos, t=np.linspace(0, 100, n), v_n=np.ones((n, 3)))


def test_s0_factors_in_separate_panels_sweep_with_spread_and_seed_named(tmp_path, captured):
    M = 100
    t = np.arange(M, dtype=float)
    rng = np.random.default_rng(1)
    d = lambda f: {
        "pos_err": rng.normal(0, 1, (M, 3)),
        "vel_err": rng.normal(0, 0.1, (M, 3)),
        "sig_pos": np.ones((M, 3)),
        "sig_vel": 0.1 * np.ones((M, 3)),
        "factors": f,
    }
    detail = {"classic": d(np.ones(M)), "attenuated": d(np.full(M, 1.3)), "fading": d(1.3 + 0.01 * rng.random(M))}
    bs = np.array([0.1, 0.2, 0.254, 0.3])
    per_seed = np.array([[3.0, 4.0, 5.0], [2.0, 2.5, 3.0], [1.5, 2.0, 2.2], [1.8, 2.4, 3.1]])
    outdir = _out(tmp_path, "s0")
    outdir.mkdir(exist_ok=True)
    _experiment_figures.plot_s0(
        outdir,
        truth=_truth(),
        gidx=np.arange(M),
        t=t,
        detail=detail,
        sweep_b=bs,
        sweep_rms=per_seed.mean(1),
        b_paper=0.254,
        sweep_per_seed=per_seed,
        seed_label="seed 0 of 3",
    )
    fig = captured["factors_and_b_sweep.png"]
    fac = [ax for ax in fig.axes if ax.get_ylabel() == "inflation factor"]
    assert len(fac) == 2  # S_k and lambda_k no longer on one axis (S_k hidden under lambda_k)
    assert [_legend_texts(ax)[0].split()[0] for ax in fac] == ["S_k", "lambda_k"]
    (sweep,) = [ax for ax in fig.axes if ax.get_xlabel() == "attenuation factor b"]
    bars = [c for c in sweep.containers if isinstance(c, ErrorbarContainer)]
    assert len(bars) == 2  # min-max and +-1 std over the seeds
    segs = bars[0].lines[2][0].get_segments()  # min-max bars: from each b's min to its max
    np.testing.assert_allclose([s[:, 1].min() for s in segs], per_seed.min(1))
    np.testing.assert_allclose([s[:, 1].max() for s in segs], per_seed.max(1))
    for name in detail:
        assert "seed 0 of 3" in captured[f"errors_{name}.png"]._suptitle.get_text()


def test_s1_statistics_no_lines_between_independent_periods(tmp_path):
    P, S = 6, 2
    rng = np.random.default_rng(2)
    st = lambda: types.SimpleNamespace(m_P=rng.random((P, S)) * 1e-3, m_H=rng.random((P, S)) * 2e-3)
    res = {
        "stats": {"standard": st(), "adaptive": st()},
        "forecast_rms": {"standard": rng.random((P, S)) * 1e-3, "adaptive": rng.random((P, S)) * 1e-3},
    }
    fig = plot.plot_s1_statistics(res, _out(tmp_path, "s1_statistics.png"))
    for ax in fig.axes:
        lines = [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 1 and ln.get_marker() not in ("None", "")]
        assert len(lines) == 2 * S
        assert all(ln.get_linestyle() == "None" for ln in lines)  # markers only
        others = [ln for ln in ax.get_lines() if ln not in lines and len(ln.get_xdata()) > 1]
        assert all(np.ptp(np.asarray(ln.get_xdata(), float)) == 0 for ln in others)  # only period separators
        # the filters sit side by side within each period, not on top of each other
        xs = {ln.get_label(): np.asarray(ln.get_xdata()) for ln in lines if not ln.get_label().startswith("_")}
        assert not np.allclose(xs["standard"], xs["adaptive"])
        assert np.all(np.abs(xs["standard"] - np.arange(1, P + 1)) < 0.5)
        assert {"standard", "adaptive", "station 1", "station 2"} <= set(_legend_texts(fig.axes[0]))


def _overlaps(labels, fig):
    r = _renderer(fig)
    boxes = [lb.get_window_extent(r) for lb in labels if lb.get_visible() and lb.get_text()]
    return [(i, j) for i in range(len(boxes)) for j in range(i + 1, len(boxes)) if boxes[i].overlaps(boxes[j])]


def test_sweep_landscape_ticks_readable(tmp_path, captured):
    # a 2-D sweep over narrow log ranges: matplotlib's default labels every minor tick there
    xa = np.geomspace(1.1e-3, 3.3e-3, 5)
    xb = np.geomspace(2.2e-6, 9.5e-6, 6)
    A, B = np.meshgrid(xa, xb, indexing="ij")
    rng = np.random.default_rng(3)
    loss = (np.log(A / 2e-3) ** 2 + np.log(B / 5e-6) ** 2).reshape(-1, 1) + 1e-3 * rng.random((A.size, 8))
    outdir = _out(tmp_path, "sweep")
    outdir.mkdir(exist_ok=True)
    plot.plot_sweep(
        outdir,
        grid={"q": A.ravel(), "r": B.ravel()},
        axes=["q", "r"],
        loss=loss,
        loss_name="mean position RMS, m",
        init={"q": 2e-3, "r": 4e-6},
    )
    fig = captured["sweep_landscape.png"]
    for ax in fig.axes[:3]:
        for axis in (ax.xaxis, ax.yaxis):
            labels = [lb for lb in axis.get_ticklabels(which="both") if lb.get_text()]
            assert not _overlaps(labels, fig), f"overlapping tick labels on {axis.get_label_text()!r}"
    main = fig.axes[0]
    assert main.get_xscale() == "log" and 2 <= len([lb for lb in main.get_xticklabels() if lb.get_text()]) <= 8


def test_sweep_1d_keeps_band_and_mean(tmp_path, captured):
    x = np.linspace(0.0, 0.5, 11)
    loss = (x[:, None] - 0.25) ** 2 + 0.01 * np.random.default_rng(4).random((11, 6))
    plot.plot_sweep(tmp_path, grid={"b": x}, axes=["b"], loss=loss, loss_name="RMS, m", init={"b": 0.1})
    ax = captured["sweep_landscape.png"].axes[0]
    assert "mean over runs" in _legend_texts(ax) and "10-90 % of the runs" in _legend_texts(ax)


def test_tune_plots_the_loss_itself(tmp_path, captured):
    losses = np.array([2.0, 1.2, 1.01, 1.0001, 1.0000001])
    path = {"b": np.array([0.1, 0.2, 0.24, 0.25, 0.254])}
    outdir = _out(tmp_path, "tune")
    outdir.mkdir(exist_ok=True)
    plot.plot_tune(
        outdir,
        path=path,
        losses=losses,
        final={"b": 0.254},
        final_loss=1.0,
        landscape=None,
        loss_name="mean position RMS, m",
        start_runs=np.random.default_rng(5).random(10) + 2,
        final_runs=np.random.default_rng(6).random(10) + 1,
    )
    ax = captured["tune.png"].axes[1]
    (curve,) = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == len(losses)]
    np.testing.assert_allclose(curve.get_ydata(), losses)  # not loss - min (which dips to ~0 by construction)
    lo, hi = ax.get_ylim()
    assert lo > 0.5 and ax.get_yscale() == "linear"
    assert ax.get_ylabel() == "loss: mean position RMS, m"


def _rtk_result(P):
    rng = np.random.default_rng(7)
    xyh = rng.normal(0, 1, (P, 3))
    prec = np.abs(rng.normal(1e-3, 2e-4, (P, 3)))
    return types.SimpleNamespace(
        xyh=xyh, terminal_xyh=xyh + 0.01, raw_precision=2 * prec, precision=prec, formal_precision=prec / 2
    )


def test_rtk_title_names_files_and_points(tmp_path):
    names = ["P01", "P02", "P03", "P04"]
    fig = plot.plot_rtk(
        _rtk_result(4),
        _out(tmp_path, "rtk.png"),
        names=names,
        title="RTK 4 points from a.pos",
        h_level=np.array([0.0, 0.01, np.nan, -0.02]),
    )
    assert fig._suptitle.get_text() == "RTK 4 points from a.pos (P01 .. P04)"
    assert fig.axes[-1].get_xlabel().startswith("point name")
    assert [lb.get_text() for lb in fig.axes[-1].get_xticklabels()] == names
    many = plot.plot_rtk(_rtk_result(40), tmp_path / "rtk40.png", names=[f"Q{i}" for i in range(40)])
    assert many._suptitle.get_text() == "RTK point means: 40 points (Q0 .. Q39)"
    assert many.axes[-1].get_xlabel() == "point number 1..40 (in order of occupation)"


def test_ins_figures_keep_legends_off_the_panels(tmp_path, captured):
    M = 60
    rng = np.random.default_rng(8)
    t = np.linspace(100.0, 160.0, M)
    win = np.array([[120.0, 130.0]])
    a3 = lambda s=1.0: s * rng.normal(size=(M, 3))
    d = _out(tmp_path, "ins")
    d.mkdir(exist_ok=True)
    plot.plot_ins_differences(
        t, a3(), np.abs(a3()), a3(0.1), np.abs(a3(0.1)), win, d / "differences_to_gnss.png", title="synthetic"
    )
    plot.plot_ins_attitude(t, a3(10), a3(10), np.abs(a3(0.1)) + 0.05, win, d / "attitude.png", title="synthetic")
    plot.plot_ins_biases(
        t,
        a3(100),
        np.abs(a3(10)),
        a3(5),
        np.abs(a3()),
        win,
        d / "biases.png",
        title="synthetic",
        gyro_sm=a3(100),
        accel_sm=a3(5),
    )
    grid = np.linspace(-0.2, 0.2, 21)
    plot.plot_time_offset_likelihood(
        grid, -1e4 * (grid - 0.05) ** 2, 0.05, 0.004, d / "time_offset.png", title="synthetic"
    )
    want = {
        "time_offset.png": {"trial offsets", "estimate +-1 sigma (+50.0 +- 4.0 ms)"},
        "differences_to_gnss.png": {"simulated GNSS outage", "filter +-3 sigma", "filter - GNSS"},
        "attitude.png": {"simulated GNSS outage", "forward", "RTS smoothed", "RTS smoothed 1-sigma"},
        "biases.png": {"simulated GNSS outage", "x (right), forward +-1 sigma", "z (up), RTS smoothed"},
    }
    for name, labels in want.items():
        fig = captured[name]
        assert all(ax.get_legend() is None for ax in fig.axes)  # no legend over a panel's data
        (leg,) = fig.legends
        assert labels <= {tx.get_text() for tx in leg.get_texts()}
        r = _renderer(fig)
        lb = leg.get_window_extent(r)
        assert all(lb.y1 <= ax.get_window_extent(r).y0 + 1 for ax in fig.axes)  # below every panel


@pytest.mark.parametrize(
    "lo,hi",
    [
        (0.68, 3.6),
        (0.25, 4.0),
        (2.2e-6, 9.5e-6),
        (1.1e-3, 3.3e-3),
        (1e-3, 1e3),
        (1.8e-4, 2.0),
        (1.0, 1.05),
        (1e-12, 1e6),
    ],
)
def test_log_ticks_few_inside_and_apart(lo, hi):
    from jaxnav.plot._style import _log_ticks

    ticks = np.asarray(_log_ticks(lo, hi))
    assert 2 <= ticks.size <= 7
    assert np.all((ticks >= lo * (1 - 1e-9)) & (ticks <= hi * (1 + 1e-9)))
    gaps = np.diff(np.log10(ticks))
    assert np.all(gaps >= np.log10(hi / lo) / 7 * (1 - 1e-9))  # never crowded
    if np.log10(hi / lo) >= 1 and lo <= 1 <= hi:
        assert 1.0 in ticks  # round values first


def _tick_numbers(axis):
    """The tick labels of ``axis`` as numbers (fails on "10^0"-style or mathtext labels)."""
    texts = [lb.get_text() for lb in axis.get_ticklabels() if lb.get_text()]
    return [float(tx.replace("\u2212", "-")) for tx in texts]


def test_ins_differences_ticks_are_plain_numbers(tmp_path, captured):
    """The symmetric-log axes read as numbers ("-1", "0", "0.1", "10"), not -10^0 / 10^-1."""
    M = 200
    t = np.linspace(0.0, 120.0, M)
    drift = np.where((t > 40) & (t < 55), 0.02 * (t - 40) ** 2, 0.0)
    d = np.stack([drift, -drift, 0.01 * np.sin(t)], axis=1)
    s = np.full((M, 3), 0.01)
    plot.plot_ins_differences(
        t, d, s, d / 10, s, np.array([[40.0, 55.0]]), tmp_path / "differences_to_gnss.png", title="synthetic"
    )
    fig = captured["differences_to_gnss.png"]
    _renderer(fig)
    for ax in fig.axes:
        assert ax.get_yscale() == "symlog"
        nums = _tick_numbers(ax.yaxis)
        assert 0.0 in nums and len(nums) >= 3, nums


def test_ins_attitude_heading_unwrapped_and_sigma_in_its_own_style(tmp_path, captured):
    """Heading through north is drawn continuous (no 0/360 jumps, no gaps); the smoothed 1-sigma has
    another colour and line style than the smoothed attitude."""
    M = 100
    t = np.linspace(0.0, 100.0, M)
    heading = (300.0 + 2.0 * t) % 360.0  # crosses north at t = 30
    att = np.stack([np.zeros(M), np.zeros(M), heading], axis=1)
    plot.plot_ins_attitude(
        t, att, att, np.full((M, 3), 0.1), np.array([[40.0, 55.0]]), tmp_path / "attitude.png", title="synthetic"
    )
    fig = captured["attitude.png"]
    head, sig = fig.axes[2], fig.axes[5]
    for ln in _data_lines(head):
        y = np.asarray(ln.get_ydata(), float)
        assert np.all(np.isfinite(y)) and np.max(np.abs(np.diff(y))) < 10.0
    (sm,) = [ln for ln in head.get_lines() if ln.get_label() == "RTS smoothed"]
    (sg,) = [ln for ln in sig.get_lines() if ln.get_label() == "RTS smoothed 1-sigma"]
    assert sm.get_color() != sg.get_color() and sm.get_linestyle() != sg.get_linestyle()
    assert "unwrapped" in head.get_ylabel()


def _walk_inputs(K=16):
    """A 9-minute drive on a small loop with K outages whose starts lie close together."""
    M = 2160
    t = np.linspace(0.0, 540.0, M)
    ref = np.stack([20 * np.cos(t / 30), 20 * np.sin(t / 30), np.zeros(M)], axis=1)
    windows = np.array([[30.0 + 30 * k, 45.0 + 30 * k] for k in range(K)])
    inside = np.zeros(M, bool)
    err = np.zeros(M)
    for a, b in windows:
        w = (t >= a) & (t < b)
        inside |= w
        err[w] = 0.02 * (t[w] - a) ** 2
    n_ref = np.array([60] * (K - 1) + [0])
    fmax = np.array([err[(t >= a) & (t < b)].max() for a, b in windows])
    scores = types.SimpleNamespace(
        windows=windows,
        t=t,
        err_fwd=err,
        err_sm=err / 10,
        n_ref=n_ref,
        fwd_max=np.where(n_ref > 0, fmax, np.nan),
        sm_max=np.where(n_ref > 0, fmax / 10, np.nan),
        fwd_rms_all=1.0,
        sm_rms_all=0.1,
    )
    return scores, dict(enu_ref=ref, enu_fwd=ref + 0.5, enu_sm=ref + 0.05)


def test_walk_outages_one_legend_entry_per_solution_and_labels_apart(tmp_path, captured):
    scores, extras = _walk_inputs()
    _ins.plot_outage_track(
        scores,
        extras["enu_ref"],
        extras["enu_fwd"],
        extras["enu_sm"],
        tmp_path / "track_outages.png",
        title="synthetic",
    )
    fig = captured["track_outages.png"]
    track, errors = fig.axes
    texts = _legend_texts(errors)
    assert len(texts) == 3, texts  # forward, RTS, the unscored outage: not one entry per outage
    assert "15 outages" in texts[0] and "1 outage(s) without an RTK-fixed epoch" in texts[2]
    labels = [tx for tx in track.texts if tx.get_text()]
    assert labels and not _overlaps(labels, fig)
    assert len([ln for ln in errors.get_lines() if len(ln.get_xdata())]) == 2 * 15  # every scored outage drawn


def test_rtk_points_are_marks_not_a_line(tmp_path):
    fig = plot.plot_rtk(_rtk_result(5), tmp_path / "rtk.png", names=[f"P{i}" for i in range(5)], h_level=np.zeros(5))
    for ax in fig.axes:
        data = [ln for ln in ax.get_lines() if len(np.atleast_1d(ln.get_xdata())) == 5]
        assert data and all(ln.get_linestyle() == "None" for ln in data), [ln.get_label() for ln in data]


def test_monte_carlo_histograms_count_whole_runs(tmp_path, captured):
    x = np.linspace(0.0, 1.0, 10)
    loss = 1.0 + x[:, None] + 0.3 * np.random.default_rng(9).random((10, 8))
    plot.plot_sweep(tmp_path, grid={"b": x}, axes=["b"], loss=loss, loss_name="RMS, m", init={"b": 0.5})
    fig = captured["sweep_landscape.png"]
    _renderer(fig)
    ticks = _tick_numbers(fig.axes[1].yaxis)
    assert ticks and all(v == int(v) for v in ticks), ticks
    plot.plot_tune(
        tmp_path,
        path={"b": np.array([0.1, 0.2])},
        losses=np.array([2.0, 1.0]),
        final={"b": 0.2},
        final_loss=1.0,
        landscape=None,
        loss_name="RMS, m",
        start_runs=np.arange(8.0) / 8 + 2,
        final_runs=np.arange(8.0) / 8 + 1,
    )
    fig = captured["tune.png"]
    _renderer(fig)
    ticks = _tick_numbers(fig.axes[2].yaxis)
    assert ticks and all(v == int(v) for v in ticks), ticks
