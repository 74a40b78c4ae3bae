"""Random stable linear Gaussian models for tests (numpy, float64)."""

import numpy as np


def random_spd(rng, n, scale=1.0, cond=10.0):
    A = rng.normal(size=(n, n))
    U, _ = np.linalg.qr(A)
    w = scale * np.exp(rng.uniform(0.0, np.log(cond), size=n))
    return (U * w) @ U.T


def random_stable_model(rng, n, m, T=None, *, radius=0.98):
    """F with spectral radius <= radius, random H, SPD Q and R; time-varying if T is given."""

    def F_():
        A = rng.normal(size=(n, n))
        return radius * A / max(np.abs(np.linalg.eigvals(A)).max(), 1e-12)

    def one():
        return F_(), rng.normal(size=(m, n)), random_spd(rng, n, 0.1), random_spd(rng, m, 0.5)

    if T is None:
        return one()
    F, H, Q, R = one()
    Fs = np.stack([F + 0.02 * rng.normal(size=(n, n)) for _ in range(T)])
    Hs = np.stack([H + 0.1 * rng.normal(size=(m, n)) for _ in range(T)])
    Qs = np.stack([random_spd(rng, n, 0.1) for _ in range(T)])
    Rs = np.stack([random_spd(rng, m, 0.5) for _ in range(T)])
    return Fs, Hs, Qs, Rs


def simulate(rng, F, H, Q, R, x0, T):
    """Draw truth and measurements from a (possibly time-varying) model."""
    n, m = x0.shape[0], (H.shape[-2])
    tv = F.ndim == 3
    xs, zs = [], []
    x = x0
    for t in range(T):
        Ft, Ht, Qt, Rt = (F[t], H[t], Q[t], R[t]) if tv else (F, H, Q, R)
        x = Ft @ x + rng.multivariate_normal(np.zeros(n), Qt)
        xs.append(x)
        zs.append(Ht @ x + rng.multivariate_normal(np.zeros(m), Rt))
    return np.array(xs), np.array(zs)
