"""Helmert 7-parameter and 4-parameter similarities: PROJ's vectors, pyproj, estimation from common points."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _paths import DATA_ROOT
from reference.proj_run import proj_available, proj_transform

from jaxnav import geodesy as g
from jaxnav.units import ARCSEC

GIE = DATA_ROOT / "proj_reference_values" / "helmert_more_builtins_excerpt.gie"


def _gie_blocks():
    """(operation parameters dict, tolerance m, [(accept, expect)]) of every helmert block."""
    text = GIE.read_text()
    text = re.sub(r"\\\n", " ", text)
    blocks, cur = [], None
    for line in text.splitlines():
        line = line.split("#")[0].strip()
        if not line or line.startswith("---"):
            continue
        w = line.split()
        if w[0] == "operation":
            op = " ".join(w[1:]).replace(" = ", "=").replace(" =", "=").replace("= ", "=")
            params = {}
            for tok in op.replace("+", " ").split():
                if "=" in tok:
                    k, v = tok.split("=", 1)
                    params[k] = v
                else:
                    params[tok] = True
            cur = dict(params=params, tol=None, pairs=[])
            blocks.append(cur)
        elif w[0] == "tolerance":
            cur["tol"] = float(w[1]) * {"um": 1e-6, "mm": 1e-3, "m": 1.0}[w[2]]
        elif w[0] == "accept":
            cur["acc"] = [float(v) for v in w[1:]]
        elif w[0] == "expect":
            cur["pairs"].append((cur["acc"], [float(v) for v in w[1:]]))
    return blocks


BLOCKS = _gie_blocks()


def test_all_vector_blocks_parsed():
    assert len(BLOCKS) == 6 and sum(len(b["pairs"]) for b in BLOCKS) == 7


@pytest.mark.parametrize(
    "block",
    [b for b in BLOCKS if "theta" not in b["params"]],
    ids=lambda b: f"{b['params'].get('convention', 'position_vector')}-{len(b['pairs'])}",
)
def test_7_parameter_against_proj_vectors(block):
    """Both rotation conventions, exact and first-order, and time-dependent (14-parameter) cases."""
    p = block["params"]
    f = lambda k: float(p.get(k, 0.0))
    conv = p.get("convention", "position_vector")
    for acc, exp in block["pairs"]:
        dt = acc[3] - f("t_epoch") if len(acc) > 3 and "t_epoch" in p else 0.0
        # 14 parameters: each parameter drifts linearly from t_epoch (PROJ's model)
        par = g.Helmert7(
            t=jnp.array([f("x") + dt * f("dx"), f("y") + dt * f("dy"), f("z") + dt * f("dz")]),
            r=jnp.array([f("rx") + dt * f("drx"), f("ry") + dt * f("dry"), f("rz") + dt * f("drz")]) * ARCSEC,
            s=(f("s") + dt * f("ds")) * 1e-6,
        )
        out = g.helmert7(par, jnp.array(acc[:3]), convention=conv, exact=bool(p.get("exact", False)))
        assert np.max(np.abs(np.asarray(out) - exp[:3])) <= block["tol"], (acc, exp)
        back = g.helmert7_inverse(par, out, convention=conv, exact=bool(p.get("exact", False)))
        np.testing.assert_allclose(back, acc[:3], rtol=0, atol=1e-8)


def test_4_parameter_against_proj_vector():
    """PROJ's 2-D helmert is x' = t + s R(-theta) x: theta_PROJ = -theta, s_PROJ = 1 + m."""
    (b,) = [b for b in BLOCKS if "theta" in b["params"]]
    p = b["params"]
    par = g.Similarity2D(
        t=jnp.array([float(p["x"]), float(p["y"])]), theta=-float(p["theta"]) * ARCSEC, m=float(p["s"]) - 1.0
    )
    ((acc, exp),) = b["pairs"]
    out = g.similarity2d(par, jnp.array(acc[:2]))
    assert np.max(np.abs(np.asarray(out) - exp[:2])) <= b["tol"]
    np.testing.assert_allclose(g.similarity2d_inverse(par, out), acc[:2], atol=1e-8)


@pytest.mark.parametrize("exact", [False, True])
@pytest.mark.parametrize("convention", ["position_vector", "coordinate_frame"])
def test_7_parameter_against_pyproj_random(convention, exact):
    if not proj_available():
        pytest.skip("pyproj is not installed")
    rng = np.random.default_rng(3)
    for _ in range(5):
        t = [float(v) for v in rng.uniform(-200, 200, 3)]
        r = [float(v) for v in rng.uniform(-20, 20, 3)]  # arc-seconds (large: exact and first order differ)
        s = float(rng.uniform(-10, 10))  # ppm
        X = rng.uniform(-6.4e6, 6.4e6, (20, 3))
        op = (
            f"+proj=helmert +convention={convention} {'+exact' if exact else ''} +x={t[0]!r} +y={t[1]!r} "
            f"+z={t[2]!r} +rx={r[0]!r} +ry={r[1]!r} +rz={r[2]!r} +s={s!r}"
        )
        ref = proj_transform([(op, (X[:, 0], X[:, 1], X[:, 2]), "FORWARD")])[0].T
        par = g.Helmert7(t=jnp.asarray(t), r=jnp.asarray(r) * ARCSEC, s=s * 1e-6)
        out = np.asarray(g.helmert7(par, jnp.asarray(X), convention=convention, exact=exact))
        assert np.max(np.abs(out - ref)) < 1e-6


def test_conventions_have_opposite_rotations():
    par = g.Helmert7(t=jnp.zeros(3), r=jnp.array([1e-5, -2e-5, 3e-5]), s=0.0)
    npar = par._replace(r=-par.r)
    X = jnp.array([[4e6, 1e6, 4.7e6]])
    # (to first order; the exact matrices are transposes, R3 R2 R1 vs R1^T R2^T R3^T)
    np.testing.assert_allclose(
        g.helmert7(par, X, convention="position_vector"),
        g.helmert7(npar, X, convention="coordinate_frame"),
        atol=1e-9,
        rtol=0,
    )
    # position vector: a positive rz turns a vector on the x axis towards +y
    out = g.helmert7(g.Helmert7(t=jnp.zeros(3), r=jnp.array([0.0, 0.0, 1e-6]), s=0.0), jnp.array([1e6, 0.0, 0.0]))
    assert float(out[1]) == pytest.approx(1.0)


@pytest.fixture(scope="module")
def sim7():
    """Control network of 8 points over ~20 km, WGS-84 -> a Beijing-1954-like frame, 5 mm noise."""
    rng = np.random.default_rng(7)
    lat = np.radians(32.8 + rng.uniform(-0.1, 0.1, 8))
    lon = np.radians(116.8 + rng.uniform(-0.1, 0.1, 8))
    X = np.stack([np.asarray(c) for c in g.geodetic_to_ecef(jnp.asarray(lat), jnp.asarray(lon), jnp.full(8, 30.0))], -1)
    true = g.Helmert7(t=jnp.array([-15.8, 150.3, 86.2]), r=jnp.array([0.82, -1.73, 2.41]) * ARCSEC, s=-3.4e-6)
    Y = np.asarray(g.helmert7(true, jnp.asarray(X))) + rng.normal(0, 0.005, (8, 3))
    return X, Y, true


def test_estimate_helmert7_recovers_parameters(sim7):
    X, Y, true = sim7
    fit = g.estimate_helmert7(jnp.asarray(X), jnp.asarray(Y))
    assert fit.dof == 17 and 0.002 < float(fit.sigma0) < 0.009  # 5 mm noise
    assert fit.residuals.shape == (8, 3) and float(jnp.max(jnp.abs(fit.residuals))) < 0.02
    # the recovered parameters reproduce the true transformation at the points to the noise level
    d = np.asarray(g.helmert7(fit.params, jnp.asarray(X)) - g.helmert7(true, jnp.asarray(X)))
    assert np.max(np.abs(d)) < 0.01
    est = np.concatenate([np.asarray(fit.params.t), np.asarray(fit.params.r), [float(fit.params.s)]])
    tru = np.concatenate([np.asarray(true.t), np.asarray(true.r), [true.s]])
    z = (est - tru) / np.asarray(fit.std)
    assert np.all(np.abs(z) < 4.5), z  # within the reported precision
    # over a 20 km network the translation and rotations are strongly correlated: large formal std
    assert float(fit.std[0]) > 1.0 and float(fit.std[6]) < 2e-6


def test_estimate_helmert7_noise_free_exact_and_weights(sim7):
    X, _, true = sim7
    Y = g.helmert7(true, jnp.asarray(X), convention="coordinate_frame", exact=True)
    fit = g.estimate_helmert7(
        jnp.asarray(X), Y, convention="coordinate_frame", exact=True, weights=jnp.arange(1.0, 9.0)
    )
    np.testing.assert_allclose(fit.params.t, true.t, atol=1e-5)
    np.testing.assert_allclose(fit.params.r, true.r, atol=1e-11)
    assert abs(float(fit.params.s) - true.s) < 1e-12 and float(fit.sigma0) < 1e-6


def test_estimate_similarity2d_recovers_parameters_and_precision():
    rng = np.random.default_rng(11)
    src = np.stack([3.63e6 + rng.uniform(-2000, 2000, 10), 4.86e5 + rng.uniform(-2000, 2000, 10)], -1)
    true = g.Similarity2D(t=jnp.array([-52.37, 96.81]), theta=jnp.float64(2.3 * ARCSEC), m=-4.2e-6)
    noise = 0.003
    keys = jax.random.split(jax.random.PRNGKey(0), 200)

    def one(k):
        dst = g.similarity2d(true, jnp.asarray(src)) + noise * jax.random.normal(k, (10, 2))
        f = g.estimate_similarity2d(jnp.asarray(src), dst)
        return jnp.stack([f.params.t[0], f.params.t[1], f.params.theta, f.params.m]), f.std, f.sigma0

    est, std, s0 = jax.vmap(one)(keys)  # vmapped Monte Carlo of the estimator
    tru = np.array([-52.37, 96.81, 2.3 * ARCSEC, -4.2e-6])
    # unbiased, and the reported std matches the Monte Carlo spread (to 20 %)
    assert np.all(np.abs(np.mean(est, 0) - tru) < 4 * np.std(est, 0) / np.sqrt(200))
    np.testing.assert_allclose(np.mean(std, 0), np.std(est, 0), rtol=0.2)
    assert abs(float(np.sqrt(np.mean(s0**2))) - noise) < 0.0005
    f = g.estimate_similarity2d(jnp.asarray(src), g.similarity2d(true, jnp.asarray(src)))
    assert f.dof == 16 and f.residuals.shape == (10, 2) and float(jnp.max(jnp.abs(f.residuals))) < 1e-7
    np.testing.assert_allclose(
        g.similarity2d_inverse(f.params, g.similarity2d(f.params, jnp.asarray(src))), src, atol=1e-7
    )


def test_too_few_points_and_bad_shapes():
    X = jnp.ones((2, 3))
    with pytest.raises(ValueError, match="7 parameters need at least 3 common points"):
        g.estimate_helmert7(X, X)
    with pytest.raises(ValueError, match="4 parameters need at least 2 common points"):
        g.estimate_similarity2d(jnp.ones((1, 2)), jnp.ones((1, 2)))
    with pytest.raises(ValueError, match=r"\(4, 3\) and \(5, 3\)"):
        g.estimate_helmert7(jnp.ones((4, 3)), jnp.ones((5, 3)))
    with pytest.raises(ValueError, match="convention"):
        g.helmert7(g.Helmert7(jnp.zeros(3), jnp.zeros(3), 0.0), jnp.ones(3), convention="bursa")
    with pytest.raises(ValueError, match=r"expected \(\.\.\., 3\)"):
        g.helmert7(g.Helmert7(jnp.zeros(3), jnp.zeros(3), 0.0), jnp.ones(2))
    # exactly determined: parameters found, sigma0 undefined (NaN), no crash
    f = g.estimate_similarity2d(jnp.array([[0.0, 0.0], [100.0, 0.0]]), jnp.array([[1.0, 2.0], [1.0, 102.0]]))
    assert f.dof == 0 and np.isnan(float(f.sigma0))
    assert float(f.params.theta) == pytest.approx(np.pi / 2)


hyp = pytest.importorskip("hypothesis")
from hypothesis import given, settings
from hypothesis import strategies as st

_f = st.floats


@settings(max_examples=25, deadline=None)
@given(
    t=st.tuples(_f(-500, 500), _f(-500, 500), _f(-500, 500)),
    r=st.tuples(_f(-30, 30), _f(-30, 30), _f(-30, 30)),
    s=_f(-50, 50),
    conv=st.sampled_from(["position_vector", "coordinate_frame"]),
    exact=st.booleans(),
)
def test_property_helmert7_inverse_and_estimate(t, r, s, conv, exact):
    """Invariants: inverse(forward(X)) = X; noise-free estimation returns the parameters."""
    par = g.Helmert7(t=jnp.array(t), r=jnp.array(r) * ARCSEC, s=s * 1e-6)
    X = jnp.asarray(np.array([-2.2e6, 5.0e6, 3.0e6]) + np.random.default_rng(0).uniform(-2e4, 2e4, (8, 3)))
    Y = g.helmert7(par, X, convention=conv, exact=exact)
    np.testing.assert_allclose(g.helmert7_inverse(par, Y, convention=conv, exact=exact), X, atol=1e-7, rtol=0)
    if conv == "position_vector" and not exact:  # the estimator's compiled default (one compilation)
        fit = g.estimate_helmert7(X, Y)
        assert float(jnp.max(jnp.abs(g.helmert7(fit.params, X) - Y))) < 1e-5
        np.testing.assert_allclose(np.asarray(fit.params.r) / ARCSEC, r, atol=1e-4)


@settings(max_examples=25, deadline=None)
@given(t=st.tuples(_f(-1e5, 1e5), _f(-1e5, 1e5)), theta=_f(-3.1, 3.1), m=_f(-0.5, 0.5))
def test_property_similarity2d_inverse_and_estimate(t, theta, m):
    par = g.Similarity2D(t=jnp.array(t), theta=jnp.float64(theta), m=jnp.float64(m))
    xy = jnp.array([[3.6e6, 4.8e5], [3.601e6, 4.82e5], [3.598e6, 4.79e5]])
    out = g.similarity2d(par, xy)
    np.testing.assert_allclose(g.similarity2d_inverse(par, out), xy, atol=1e-6, rtol=0)
    fit = g.estimate_similarity2d(xy, out)
    assert abs(float(fit.params.theta) - theta) < 1e-9 and abs(float(fit.params.m) - m) < 1e-9
    np.testing.assert_allclose(fit.params.t, t, atol=1e-4)
