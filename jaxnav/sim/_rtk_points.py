"""Simulated S2 survey: P points occupied for 30-60 epochs at 2 s by a CORS-RTK terminal.

Modelled on the S2 experiment (45 points over two mining-subsidence observation lines near
Huainan, 2 s sampling, >= 30 epochs per point, levelling as the reference):

* truth: points spread over an ``area`` x ``area`` m square around (center_x, center_y); true normal heights;
  a height-anomaly field zeta = quadratic surface + a small unmodelled wave, so the true
  ellipsoidal height is H = h + zeta;
* the reference plane frame ("Beijing 1954"-like local grid) is a 4-parameter similarity of the
  WGS-84 Gauss-Krüger grid;
* RTK epoch errors: a first-order Gauss-Markov (correlated) part plus white noise, per axis
  (x north, y east, up); the terminal reports per-epoch standard errors scattered around the
  true total standard deviation;
* the terminal's fitted height h carries a systematic error per point (its built-in height
  model is off: mean ``terminal_bias`` with spread ``terminal_bias_spread``), as in S2 Table 3;
* a connection survey: ``n_control`` (<= 9) control points on a jittered 3 x 3 grid covering the
  area, with GNSS (B, L, H) of a few mm and levelled normal heights, plus their reference-frame plane
  coordinates;
* levelling of every point with ``levelling_sigma``.

All draws come from one explicit PRNG key; shapes are static ((P, max_epochs) padded with a mask).
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxnav.geodesy import WGS84, Similarity2D, enu_to_curvilinear, gauss_kruger_inverse, similarity2d


class RtkPointsConfig(NamedTuple):
    """Settings of the simulated S2 survey (SI units; angles rad).

    Attributes:
      n_points: P (static).  min_epochs, max_epochs: epoch count range per point (static).
      dt: sampling interval, s.  center_x, center_y: area centre in WGS-84 Gauss-Krüger (x north,
        y east incl. 500 km, no zone prefix), m.  lon_cm: GK central meridian, rad.
      area: side of the square area, m.  h_mean, h_spread: true normal heights, m.
      zeta0: height anomaly at the centre, m.  zeta_grad: (2,) anomaly gradient (north, east), m/m.
      zeta_curv: (3,) quadratic terms (xx, xy, yy), m/m^2.  zeta_wave: amplitude of the unmodelled
        part (one sinusoid over the area), m.
      markov_sigma: (3,) steady std of the correlated error (north, east, up), m.
      markov_tau: (3,) its correlation time, s.  white_sigma: (3,) white-noise std, m.
      sigma_report_spread: relative scatter of the reported standard errors.
      terminal_bias, terminal_bias_spread: systematic error of the terminal's fitted heights, m.
      n_control: control points (static).  control_sigma: (3,) their GNSS errors (n, e, up), m.
      levelling_sigma: std of the levelled heights, m.
      datum: :class:`jaxnav.geodesy.Similarity2D` WGS-84 GK -> reference grid.
    """

    n_points: int = 45
    min_epochs: int = 30
    max_epochs: int = 60
    dt: float = 2.0
    center_x: float = 3_631_500.0  # GK north of the area centre (about 32.81 N), m
    center_y: float = 486_000.0  # GK east without zone prefix (about 116.85 E), m
    lon_cm: float = 2.0420352248333655  # 117 deg (3-degree zone 39), rad
    area: float = 3000.0
    h_mean: float = 22.0
    h_spread: float = 1.5
    zeta0: float = -3.45
    zeta_grad: tuple = (1.8e-5, -2.6e-5)
    zeta_curv: tuple = (2.0e-10, -1.0e-10, 1.5e-10)
    zeta_wave: float = 0.002
    markov_sigma: tuple = (0.004, 0.004, 0.008)
    markov_tau: tuple = (40.0, 40.0, 60.0)
    white_sigma: tuple = (0.004, 0.004, 0.008)
    sigma_report_spread: float = 0.15
    terminal_bias: float = 0.08
    terminal_bias_spread: float = 0.01
    n_control: int = 8
    control_sigma: tuple = (0.002, 0.002, 0.003)
    levelling_sigma: float = 0.001
    datum: Similarity2D = Similarity2D(t=(-52.37, 96.81), theta=1.1e-5, m=-4.2e-6)


class RtkPointsSim(NamedTuple):
    """A simulated S2 survey (P points, T = max_epochs, C control points).

    Attributes:
      t: (P, T) s.  mask: (P, T) bool.  n: (P,) epoch counts.
      lat, lon: (P, T) measured WGS-84 latitude, longitude, rad.  H: (P, T) measured ellipsoidal height, m.
      sigma: (P, T, 3) reported standard errors (x north, y east, h), m.
      xy_terminal: (P, T, 2) terminal's reference-grid coordinates, m.  h_terminal: (P, T) its fitted heights, m.
      true_lat, true_lon: (P,) rad.  true_H: (P,) m.  true_h: (P,) normal heights, m.
      true_xy: (P, 2) reference-grid coordinates, m.  true_zeta: (P,) height anomalies, m.
      h_level: (P,) levelled heights, m.
      control_lat, control_lon, control_H: (C,) measured control coordinates (rad, m).
      control_xy: (C, 2) reference-grid coordinates, m.  control_h: (C,) levelled normal heights, m.
    """

    t: jax.Array
    mask: jax.Array
    n: jax.Array
    lat: jax.Array
    lon: jax.Array
    H: jax.Array
    sigma: jax.Array
    xy_terminal: jax.Array
    h_terminal: jax.Array
    true_lat: jax.Array
    true_lon: jax.Array
    true_H: jax.Array
    true_h: jax.Array
    true_xy: jax.Array
    true_zeta: jax.Array
    h_level: jax.Array
    control_lat: jax.Array
    control_lon: jax.Array
    control_H: jax.Array
    control_xy: jax.Array
    control_h: jax.Array


def true_height_anomaly(cfg: RtkPointsConfig, dx, dy):
    """The simulated anomaly field zeta at offsets (dx north, dy east) from the centre, m."""
    g, c = cfg.zeta_grad, cfg.zeta_curv
    wave = cfg.zeta_wave * jnp.sin(2 * jnp.pi * dx / cfg.area) * jnp.cos(2 * jnp.pi * dy / cfg.area)
    return cfg.zeta0 + g[0] * dx + g[1] * dy + c[0] * dx * dx + c[1] * dx * dy + c[2] * dy * dy + wave


def _enu_to_latlon(lat, lon, dn, de, ell):
    """Small horizontal offsets (m) -> geodetic lat, lon (rad), to first order (mm over 10 cm).

    The radii are taken on the ellipsoid (h = 0): the heights of the area (~20 m) would change
    the cm-level offsets by ~3e-6 of their size.
    """
    d = enu_to_curvilinear(
        jnp.stack([lat, lon, jnp.zeros_like(lat)], -1), jnp.stack([de, dn, jnp.zeros_like(de)], -1), ell
    )
    return lat + d[..., 0], lon + d[..., 1]


@partial(jax.jit, static_argnames=("cfg",))
def simulate_rtk_points(key, cfg: RtkPointsConfig = RtkPointsConfig()) -> RtkPointsSim:
    """Simulate the S2 survey described in the module docstring.

    Args:
      key: PRNG key.
      cfg: :class:`RtkPointsConfig`, static (hashable: tuples, not arrays); jitted once per config.
    Returns:
      :class:`RtkPointsSim`.
    """
    ell = WGS84
    P, T, C = cfg.n_points, cfg.max_epochs, cfg.n_control
    ku, kn, kr = jax.random.split(key, 3)
    # all normal draws in one call (one threefry block to compile), sliced below
    sizes = dict(h=P, drive=T * P * 3, white=P * T * 3, sig=P * T * 3, bias=P, lev=P, ch=C, ce=C * 3, cl=C)
    flat = jax.random.normal(kn, (sum(sizes.values()),))
    draw, o = {}, 0
    for name, size in sizes.items():
        draw[name] = flat[o : o + size]
        o += size
    x_c, y_c = cfg.center_x, cfg.center_y
    # survey points uniform over the square; control points of the connection survey spread
    # over a slightly larger square (a jittered 3 x 3 grid of spacing 0.55 area, first C cells:
    # a control network covers the area it serves; a ring alone would make the quadratic
    # surface singular, x^2 + y^2 = const)
    u = jax.random.uniform(ku, (2 * P + 2 * C,))
    d_pts = (u[: 2 * P].reshape(P, 2) - 0.5) * cfg.area
    cell = jnp.stack([jnp.arange(C) // 3 - 1.0, jnp.arange(C) % 3 - 1.0], -1)
    d_cp = (0.55 * cell + 0.3 * (u[2 * P :].reshape(C, 2) - 0.5)) * cfg.area
    d_all = jnp.concatenate([d_pts, d_cp])
    gk_all = jnp.stack([x_c + d_all[:, 0], y_c + d_all[:, 1]], -1)
    lat_all, lon_all = gauss_kruger_inverse(gk_all[:, 0], gk_all[:, 1], lon0=cfg.lon_cm, ellipsoid=ell)
    d, lat, lon, gk = d_all[:P], lat_all[:P], lon_all[:P], gk_all[:P]
    h = cfg.h_mean + cfg.h_spread * draw["h"]
    zeta = true_height_anomaly(cfg, d[:, 0], d[:, 1])
    Ht = h + zeta
    datum = Similarity2D(*[jnp.asarray(v, float) for v in cfg.datum])
    xy_true = similarity2d(datum, gk)

    n = jax.random.randint(kr, (P,), cfg.min_epochs, cfg.max_epochs + 1)
    mask = jnp.arange(T)[None, :] < n[:, None]
    t0 = 3600.0 * 9 + 150.0 * jnp.arange(P)  # points occupied one after another
    t = t0[:, None] + cfg.dt * jnp.arange(T)[None, :]
    ms, mt, ws = (jnp.asarray(v, float) for v in (cfg.markov_sigma, cfg.markov_tau, cfg.white_sigma))
    # first-order Gauss-Markov, stationary from the first epoch, all points at once (one scan
    # over T on a (P, 3) state; cheaper to compile than P per-sequence generators)
    phi = jnp.exp(-cfg.dt / mt)
    drive = draw["drive"].reshape(T, P, 3)
    x0 = ms * drive[0]
    _, corr = jax.lax.scan(lambda x, w: (phi * x + ms * jnp.sqrt(1.0 - phi**2) * w,) * 2, x0, drive[1:])
    corr = jnp.concatenate([x0[None], corr], axis=0).transpose(1, 0, 2)
    err = corr + ws * draw["white"].reshape(P, T, 3)  # (north, east, up)
    tot = jnp.sqrt(ms**2 + ws**2)
    sigma = tot * (1.0 + cfg.sigma_report_spread * draw["sig"].reshape(P, T, 3))
    sigma = jnp.clip(sigma, 0.3 * tot, 3.0 * tot)
    la, lo = _enu_to_latlon(lat[:, None], lon[:, None], err[..., 0], err[..., 1], ell)
    H = Ht[:, None] + err[..., 2]
    # the terminal's grid coordinates: the cm-level errors rotated by the meridian convergence
    # (~1e-3 rad here) would move them by ~10 um, ignored
    xy_term = similarity2d(datum, gk[:, None, :] + err[..., :2])
    bias = cfg.terminal_bias + cfg.terminal_bias_spread * draw["bias"]
    h_term = h[:, None] + bias[:, None] + err[..., 2]
    h_level = h + cfg.levelling_sigma * draw["lev"]

    # control points of the connection survey: GNSS (B, L, H) and levelled heights
    dcp, clat, clon = d_all[P:], lat_all[P:], lon_all[P:]
    ch_true = cfg.h_mean + cfg.h_spread * draw["ch"]
    cH = ch_true + true_height_anomaly(cfg, dcp[:, 0], dcp[:, 1])
    ce = jnp.asarray(cfg.control_sigma, float) * draw["ce"].reshape(C, 3)
    clat_m, clon_m = _enu_to_latlon(clat, clon, ce[:, 0], ce[:, 1], ell)
    cxy = similarity2d(datum, gk_all[P:])
    ch = ch_true + cfg.levelling_sigma * draw["cl"]

    nanT = lambda a: jnp.where(mask if a.ndim == 2 else mask[..., None], a, jnp.nan)
    return RtkPointsSim(
        t=t,
        mask=mask,
        n=n,
        lat=nanT(la),
        lon=nanT(lo),
        H=nanT(H),
        sigma=nanT(sigma),
        xy_terminal=nanT(xy_term),
        h_terminal=nanT(h_term),
        true_lat=lat,
        true_lon=lon,
        true_H=Ht,
        true_h=h,
        true_xy=xy_true,
        true_zeta=zeta,
        h_level=h_level,
        control_lat=clat_m,
        control_lon=clon_m,
        control_H=cH + ce[:, 2],
        control_xy=cxy,
        control_h=ch,
    )
