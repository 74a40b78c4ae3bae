"""S3 cadastral pipeline: classes 1-3 on a short simulated survey, reverse navigation, fusion, bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxnav
from jaxnav import ins
from jaxnav.sim import cadastral_scenarios, short_survey, simulate_cadastral, survey_truth
from jaxnav.survey import (
    STAGES,
    detect_stops,
    make_stop_list,
    match_stops,
    plan_survey,
    preprocess_imu,
    process_survey,
    strapdown_with_resets,
    summarize_errors,
    target_errors,
)
from jaxnav.survey.cadastral import propagate_covariances


@pytest.fixture(scope="module")
def survey():
    from jaxnav.experiments.s3 import detector_params_for, grade_params

    scns, pipe = cadastral_scenarios()
    scn = short_survey(scns["tactical"], 3)  # K0, Z1, T1, K1: one target between two known points
    truth = survey_truth(scn)
    plan = plan_survey(truth.stops, truth.t_imu)
    params = grade_params(scn, pipe)
    det = detector_params_for(scn)
    tpos = jnp.asarray(truth.pos[plan.arrival])

    def one(key):
        run = simulate_cadastral(scn, key, truth)
        out = process_survey(plan, run.nav0, run.dtheta, run.dv, run.known_pos, params)
        pre = preprocess_imu(run.dtheta, run.dv, scn.dt, params.pre, lowpass=False)
        return dict(
            err=target_errors(out, tpos),
            n_rej=out.n_rejected,
            n_wild=run.n_wild,
            status=out.status,
            sf=out.sigma_forward,
            sb=out.sigma_backward,
            w=out.weight_forward,
            f=pre.dv / scn.dt,
            g=pre.dtheta / scn.dt,
            nav0=run.nav0,
            dth=run.dtheta,
            dv=run.dv,
        )

    # one seed keeps the module's compile-and-run time down; the CLI runs the 64-seed Monte Carlo
    res = jax.tree_util.tree_map(lambda a: a[None], jax.jit(one)(jax.random.PRNGKey(0)))
    return scn, truth, plan, params, det, res


def test_plan_layout(survey):
    scn, truth, plan, *_ = survey
    assert [plan.stops.name[k] for k in plan.targets] == ["T1"]
    assert plan.has_next.tolist() == [True] and plan.class3.tolist() == [False]  # T1 follows a ZUPT point
    # every stop epoch observes zero velocity; K0 and K1 their coordinates once; Z1/T1 nothing else
    assert plan.meas_mask[plan.meas_stop >= 0, 3:].all() and not plan.meas_mask[plan.meas_stop < 0].any()
    assert plan.meas_mask[:, :3].all(1).sum() == 2 and plan.meas_mask[:, :3].any(1).sum() == 2
    # target arrival/departure states are the stop boundaries on the sample grid
    t_grid = np.concatenate([[0.0], truth.t_imu])
    k = plan.targets[0]
    assert t_grid[plan.arrival[0]] == pytest.approx(plan.stops.t_start[k])
    assert t_grid[plan.departure[0]] == pytest.approx(plan.stops.t_end[k])


def test_stage_gains(survey):
    """(a) >> (b) > (c): compensation at stops and reverse-navigation fusion each help; (c) <= 0.7 (a)."""
    *_, res = survey
    e = res["err"]
    h = {s: np.hypot(np.asarray(e[s])[..., 0], np.asarray(e[s])[..., 1]) for s in STAGES}
    v = {s: np.abs(np.asarray(e[s])[..., 2]) for s in STAGES}
    assert np.all(h["fused"] <= 0.7 * h["forward"]) and np.all(v["fused"] <= 0.7 * v["forward"])
    assert np.all(h["smoothed"] < 0.2 * h["preprocessed"])
    assert np.all(h["fused"] < 2.0) and np.all(v["fused"] < 0.2)
    assert np.all(h["rts"] < 0.5)
    s = summarize_errors({k: np.asarray(x) for k, x in e.items()})
    assert s["fused"]["ratio_h_vs_forward"] <= 0.7
    assert s["fused"]["rms_h"] <= s["smoothed"]["rms_h"] * 1.05
    # inverse-variance weights lie in (0, 1) and follow the propagated sigmas
    w, sf, sb = (np.asarray(res[k]) for k in ("w", "sf", "sb"))
    np.testing.assert_allclose(w, sb**2 / (sf**2 + sb**2), rtol=1e-9)


def test_wild_values_rejected_and_status_clean(survey):
    *_, res = survey
    n_rej, n_wild = np.asarray(res["n_rej"]), np.asarray(res["n_wild"])
    assert np.all(n_wild > 0)
    # (nearly) every injected wild value is found, and the walking dynamics raise (almost) no false alarms
    assert np.all(n_rej >= 0.9 * n_wild) and np.all(n_rej <= n_wild + 10)
    for st in np.asarray(res["status"]):
        jaxnav.raise_for_status(int(st))


def test_detector_finds_simulated_stops(survey):
    scn, truth, plan, params, det, res = survey
    true = np.stack([truth.stops.t_start, truth.stops.t_end], 1)
    for i in range(1):
        r = detect_stops(truth.t_imu, np.asarray(res["f"][i]), np.asarray(res["g"][i]), det, window=50)
        sc = match_stops(r.spans, true, t=truth.t_imu, static=r.static)
        assert sc.precision == 1.0 and sc.recall == 1.0
        assert sc.sample_precision > 0.99 and sc.sample_recall > 0.97
        assert np.all(np.abs(sc.start_error) < 0.5) and np.all(np.abs(sc.end_error) < 0.5)


def test_reverse_navigation_retraces_forward(survey):
    """Without resets, the reverse run from the forward end state comes back to the start (S3 class 3)
    and equals jaxnav.ins.mechanize_backward."""
    scn, truth, plan, params, det, res = survey
    n = 3000
    nav0 = jax.tree_util.tree_map(lambda a: a[0], res["nav0"])
    dth, dv = res["dth"][0][:n], res["dv"][0][:n]
    none = np.full(n, -1)
    tab = ins.NavState(q_bn=jnp.zeros((1, 4)).at[:, 0].set(1.0), v_n=jnp.zeros((1, 3)), pos=nav0.pos[None])
    mech = ins.mechanize(nav0, dth, dv, scn.dt)
    pos_b, _ = strapdown_with_resets(mech.final.nav, dth, dv, scn.dt, none, tab, backward=True)
    from jaxnav.survey.cadastral import enu_difference

    assert float(jnp.max(jnp.abs(enu_difference(pos_b[0], nav0.pos)))) < 1e-5
    back = ins.mechanize_backward(mech.final.nav, dth, dv, scn.dt)
    np.testing.assert_allclose(np.asarray(pos_b), np.asarray(back.nav.pos), rtol=0, atol=1e-12)


def test_propagate_covariances_against_numpy():
    rng = np.random.default_rng(0)
    M, n = 6, 4
    Phi = np.eye(n) + 0.1 * rng.normal(size=(M, n, n))
    Q = np.stack([np.diag(rng.uniform(0.1, 1, n)) for _ in range(M)])
    P0 = np.eye(n)
    covs = np.stack([np.diag(rng.uniform(0.5, 1, n)) for _ in range(M)])
    prev = np.concatenate([P0[None], covs[:-1]])
    pred = np.einsum("mij,mjk,mlk->mil", Phi, prev, Phi) + Q
    table = np.stack([np.eye(n) * 0.01, np.eye(n) * 0.02])
    rf = np.array([0, -1, -1, -1, -1, -1])
    rb = np.array([-1, -1, -1, -1, -1, 1])
    Pf, Pb = propagate_covariances(
        jnp.asarray(Phi), jnp.asarray(pred), jnp.asarray(covs), jnp.asarray(P0), rf, rb, jnp.asarray(table)
    )
    P = table[0]
    for j in range(1, M):
        P = Phi[j] @ P @ Phi[j].T + Q[j]
        np.testing.assert_allclose(np.asarray(Pf[j]), P, rtol=1e-10)
    P = table[1]
    for j in range(M - 1, 0, -1):
        Fi = np.linalg.inv(Phi[j])
        P = Fi @ (P + Q[j]) @ Fi.T
        np.testing.assert_allclose(np.asarray(Pb[j - 1]), P, rtol=1e-9)


def test_bad_input(survey):
    scn, truth, plan, params, *_ = survey
    s = truth.stops
    shifted = make_stop_list(s.t_start + 1e9, s.t_end + 1e9, s.kind, s.pos, s.sigma, s.name)
    with pytest.raises(ValueError, match="does not match this data"):
        plan_survey(shifted, truth.t_imu)
    longer = make_stop_list(s.t_start, s.t_end + np.r_[0, 0, 0, 500.0], s.kind, s.pos, s.sigma, s.name)
    with pytest.raises(ValueError, match="does not match this data"):
        plan_survey(longer, truth.t_imu)
    kinds = s.kind.copy()
    kinds[0] = 3  # the start point is no longer a known-coordinate point
    with pytest.raises(ValueError, match="T1.*no known-coordinate point before it"):
        plan_survey(make_stop_list(s.t_start, s.t_end, kinds, s.pos, s.sigma, s.name), truth.t_imu)
    with pytest.raises(ValueError, match="too short"):
        plan_survey(
            make_stop_list(s.t_start, s.t_start + np.r_[40, 10, 0.6, 15], s.kind, s.pos, s.sigma, s.name), truth.t_imu
        )
    with pytest.raises(ValueError, match=r"must be \(\d+, 3\)"):
        process_survey(plan, None, jnp.zeros((10, 3)), jnp.zeros((10, 3)), s.pos, params)
