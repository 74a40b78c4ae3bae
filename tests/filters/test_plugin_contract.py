"""The plug-in contract: the protocols' default methods, one return shape per method, one pytree
style (rebuilding skips the constructor's checks), constructors that check their arguments as
the lower-case functions do, and records whose fields are declared classes."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxnav import filters as jf
from jaxnav.filters._step import ALL_OUTPUTS

pytestmark = pytest.mark.timeout(120)


def test_records_are_declared_classes_with_the_saved_outputs():
    assert jf.StepInfo._fields == ALL_OUTPUTS
    assert jf.KalmanResult._fields[: len(ALL_OUTPUTS)] == ALL_OUTPUTS
    assert jf.KalmanResult._fields[len(ALL_OUTPUTS) :] == (
        "loglik",
        "n_nonfinite",
        "n_skipped",
        "status",
        "x_final",
        "P_final",
    )
    assert jf.StepInfo() == (None,) * len(ALL_OUTPUTS)


@pytest.mark.parametrize(
    "build, match",
    [
        (lambda: jf.Constant(S=0.5), r"Constant: S must be in \[1, inf\)"),
        (lambda: jf.Attenuated(b=1.0), r"Attenuated: b must be in \[0, 1\)"),
        (lambda: jf.Fading(window=3, rho=0.5), "either window"),
        (lambda: jf.Fading(window=0), "window must be a positive integer"),
        (lambda: jf.Fading(max_factor=0.5), "max_factor"),
        (lambda: jf.Switch(index=0, rules=()), "at least one rule"),
        (lambda: jf.Switch(index=0, rules=(jf.constant(2.0, states=[0]), jf.fading(states=[1]))), "different states"),
        (lambda: jf.VarianceCompensation(window=0), "window must be a positive integer"),
        (lambda: jf.VarianceCompensation(window=5, min_epochs=9), "min_epochs"),
        (lambda: jf.VarianceCompensation(floor=-1.0), "floor"),
        (lambda: jf.SageHusa(estimate="P"), "estimate"),
        (lambda: jf.SageHusa(b=1.0), r"b must be in \(0, 1\)"),
        (lambda: jf.IGG3(k0=3.0, k1=2.0), "k0 < k1"),
        (lambda: jf.IGG3(lockout=0), "lockout"),
        (lambda: jf.YangFactor(c0=2.0, c1=1.0), "c1 > c0"),
        (lambda: jf.Chain(parts=()), "at least one estimator"),
        (lambda: jf.Chain(parts=(jf.constant(2.0),)), "not a noise estimator"),
    ],
)
def test_exported_constructors_check_their_arguments(build, match):
    with pytest.raises(ValueError, match=match):
        build()


def test_functions_and_constructors_build_the_same_objects():
    assert jax.tree.structure(jf.fading(5)) == jax.tree.structure(jf.Fading(window=5))
    assert jf.constant(2.0, states=slice(0, 3)).states == jf.Constant(S=2.0, states=range(3)).states == (0, 1, 2)
    for a, b in [(jf.sage_husa(0.9), jf.SageHusa(b=0.9)), (jf.igg3(1.5, 4.0), jf.IGG3(k0=1.5, k1=4.0))]:
        for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
            assert x.dtype == y.dtype and float(x) == float(y)


def test_rebuilding_a_pytree_skips_the_checks():
    """JAX rebuilds plug-ins from shapes, in_axes entries and tracers: none of them is a valid parameter."""
    shapes = jax.tree.map(lambda x: x.shape, jf.attenuated(0.5))
    assert shapes.b == ()
    axes = jax.tree.map(lambda _: 0, jf.constant(2.0))  # S = 0 would be refused by the constructor
    assert axes.S == 0
    rules = jax.vmap(lambda S: jf.Constant(S=S))(jnp.array([1.0, 2.0]))
    assert rules.S.shape == (2,)


def test_data_independent_is_a_property_everywhere():
    plugins = [
        jf.NoInflation(),
        jf.NoEstimator(),
        jf.constant(2.0),
        jf.attenuated(0.2),
        jf.fading(3),
        jf.switch(0, [None, jf.attenuated(0.2)]),
        jf.variance_compensation(5),
        jf.sage_husa(),
        jf.igg3(),
        jf.yang_factor(),
        jf.chain(jf.igg3()),
    ]
    got = [p.data_independent for p in plugins]
    assert got == [True, True, True, True, False, True, False, False, False, False, False]
    for p in plugins:
        assert isinstance(type(p).__dict__.get("data_independent", type(p).data_independent), property)


def test_a_subclass_inherits_the_defaults_and_runs():
    @jf.pytree_dataclass
    class Linear(jf.InflationRule):
        rate: jax.Array
        cap: jax.Array = 10.0
        states: tuple = jf.static_field(None)

        @property
        def data_independent(self):
            return True

        def factor(self, state, ctx):
            return jnp.minimum(1.0 + self.rate * ctx.k, self.cap), state, jf.no_flags()

    @jf.pytree_dataclass
    class Keep(jf.NoiseEstimator):
        def noise(self, state, ctx):
            return ctx.GQG, ctx.R_used, state, ((), jf.no_flags())

    model = jf.constant_velocity(1.0, sigma=0.1, q=1e-4, ndim=1)
    zs = np.cumsum(np.full((30, 1), 0.1), axis=0)
    x0, P0 = np.zeros(2), np.eye(2)
    a = jf.kalman_filter(model, x0, P0, zs, inflation=Linear(rate=jnp.asarray(0.0)), estimator=Keep())
    b = jf.kalman_filter(model, x0, P0, zs)
    np.testing.assert_allclose(a.means, b.means, rtol=1e-12, atol=1e-14)
    grown = jf.kalman_filter(model, x0, P0, zs, inflation=Linear(rate=jnp.asarray(0.1)), save=("factors",))
    np.testing.assert_allclose(grown.factors, np.minimum(1.0 + 0.1 * np.arange(1, 31), 10.0))
    assert isinstance(Keep(), jf.NoiseEstimator) and Keep().after((), None, None) == ()
    assert dataclasses.is_dataclass(Linear) and Linear(rate=0.1).states is None


def test_nonlinear_model_keeps_the_jacobians_it_was_given():
    f = lambda x, t: x
    h = lambda x, t: x[:1]
    m = jf.NonlinearGaussian(f, h, jnp.eye(2), jnp.eye(1))
    assert m.F_jac is None and m.H_jac is None
    np.testing.assert_array_equal(m.jacobian_h(jnp.ones(2), 0), [[1.0, 0.0]])
    leaves, tree = jax.tree.flatten(m)
    assert len(leaves) == 2 and jax.tree.unflatten(tree, leaves).f is f
    assert jax.tree.structure(jf.NonlinearGaussian(f, h, jnp.eye(2), jnp.eye(1))) == tree
