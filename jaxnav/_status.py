"""Status bit flags accumulated through scans, and their host-side conversion to errors.

Algorithms never raise inside ``jit``; they OR flags into an int32 ``status`` leaf that
travels through the scan. :func:`raise_for_status` turns a (possibly batched) status into a
readable exception after the run.
"""

from __future__ import annotations

import numpy as np

NONFINITE_MEASUREMENT = 1  # a NaN/inf measurement element was masked (information, not an error)
CHOLESKY_FAILED = 2  # an innovation covariance was not positive definite; update skipped
NONFINITE_STATE = 4  # the state or covariance became NaN/inf
ESTIMATOR_FALLBACK = 8  # a noise estimator had too little data/rank and used the prior noise
SMOOTHER_FAILED = 16  # a predicted covariance in the smoother was not positive definite
NONFINITE_UNMASKED = 32  # NaN/inf measurements reached the update (check_finite=False)
NONFINITE_IMU = 64  # a NaN/inf IMU sample reached the mechanization (it cannot skip samples)
BAD_IMU_TIME = 128  # non-positive or irregular IMU sample interval
DISCRETIZATION_INACCURATE = 256  # a truncated Taylor discretisation had not converged (use more terms or Van Loan)
COVARIANCE_INDEFINITE = 512  # an adaptive filter's covariance lost positive semi-definiteness (diverged)
IMU_INCREMENT_TOO_LARGE = 1024  # a rotation increment above pi rad in one sample (nav_every > 1)
BATCH_MASK_WIDENED = 2048  # a finite measurement was masked because another sequence of the batch had NaN/inf there
PARAMETER_OUT_OF_RANGE = 4096  # a plug-in parameter (traced, so not checked by its constructor) was outside its range
NOISE_ESTIMATE_BOUNDED = 8192  # an adaptive noise estimate (Sage-Husa R or Q) reached its bound around the model's
INFLATION_CAPPED = 16384  # an adaptive inflation factor (fading lambda_k) reached its cap
ROBUST_LOCKOUT = 32768  # a robust estimator rejected every valid measurement over many consecutive epochs
GNSS_GATED = 65536  # a GNSS epoch failed the chi-square innovation gate and was skipped (information)
FLOAT32_DATA_RANGE = 131072  # float32 with a data-dependent plug-in and a measurement beyond FLOAT32_Z_RANGE sigma

#: |z|/sigma (sigma: the model's measurement noise) up to which a data-dependent plug-in (fading,
#: Sage-Husa, variance compensation, IGG-III, Yang) keeps its variances to ~6e-5 relative in float32
FLOAT32_Z_RANGE = 100.0

_MESSAGES = {
    NONFINITE_MEASUREMENT: "non-finite measurements were masked (updates skipped for them)",
    CHOLESKY_FAILED: "an innovation covariance was not positive definite; its update was skipped",
    NONFINITE_STATE: "the state or covariance became non-finite",
    ESTIMATOR_FALLBACK: "the noise estimator fell back to the prior noise (too little data or rank)",
    SMOOTHER_FAILED: "a predicted covariance was not positive definite in the smoother",
    NONFINITE_UNMASKED: "non-finite measurements were used unmasked (check_finite=False): results are invalid",
    NONFINITE_IMU: "a NaN/inf IMU sample was mechanized: the navigation solution is invalid from there on",
    BAD_IMU_TIME: "an IMU sample interval was non-positive or non-finite",
    DISCRETIZATION_INACCURATE: "the Taylor discretisation of the error model had not converged (last term above "
    "1e-10 of Phi): raise LCDiscretization.order or use LCDiscretization('van_loan')",
    COVARIANCE_INDEFINITE: "a filtered or predicted covariance of an adaptive filter lost positive "
    "semi-definiteness (eigenvalue below -1e-10 of its largest variance): the "
    "inflation or noise estimate diverged and the results are unreliable",
    IMU_INCREMENT_TOO_LARGE: "an IMU rotation increment exceeded pi rad in one sample: the record is undersampled "
    "for strapdown integration, and the attitude series of nav_every > 1 is exact only "
    "up to 2 pi per sample (use nav_every=1)",
    BATCH_MASK_WIDENED: "finite measurements were left out because another sequence of the batch had NaN/inf at "
    "the same element (kalman_filter_batch shares one covariance recursion); for sequences "
    "with gaps of their own use jax.vmap(kalman_filter)",
    PARAMETER_OUT_OF_RANGE: "a filter plug-in parameter was outside its documented range (a traced value, e.g. "
    "under vmap/grad, that the constructor could not check): the results are not those of "
    "the documented filter",
    NOISE_ESTIMATE_BOUNDED: "an adaptive noise estimate reached its bound (Sage-Husa R or Q outside the documented factor "
    "range of the model's): the data disagree with the model by more than that factor, e.g. an "
    "unmodelled change of dynamics was being attributed to the measurement noise",
    INFLATION_CAPPED: "an adaptive prior-inflation factor reached its cap (fading lambda_k = max_factor): the "
    "innovations were far larger than the model explains (a diverging filter or model "
    "mismatch); the factor was limited there",
    ROBUST_LOCKOUT: "a robust estimator rejected every valid measurement component for many consecutive epochs "
    "(IGG-III lock-out): the filter coasted on its prediction and may have lost the truth; use "
    "max_run to accept persistent changes",
    GNSS_GATED: "GNSS epochs failed the chi-square innovation gate and were skipped (counted in n_gated)",
    FLOAT32_DATA_RANGE: "float32 with a data-dependent plug-in (fading, Sage-Husa, variance compensation, IGG-III, "
    "Yang) and a measurement more than 100 sigma from the origin: the plug-in's factor and noise "
    "come from float32 innovations whose rounding grows with |z| (variances measured 30-50 % off "
    "on long tracks); subtract a local origin from z and x0, or compute in float64",
}

#: flags that are reported but are not errors by default
INFO_FLAGS = NONFINITE_MEASUREMENT | ESTIMATOR_FALLBACK | GNSS_GATED


class StatusError(RuntimeError):
    """Raised by :func:`raise_for_status` when error flags are set."""


def status_messages(status) -> list[str]:
    """Human-readable list of the flags set in ``status`` (any shape; flags are OR-ed)."""
    s = int(np.bitwise_or.reduce(np.asarray(status, dtype=np.int64).ravel(), initial=0))
    return [msg for bit, msg in _MESSAGES.items() if s & bit]


def status_words(status) -> str:
    """``status`` (any shape; flags OR-ed) as its value and the names of its flags, for printing:
    ``"65536 (GNSS_GATED)"``, ``"0 (ok)"``."""
    s = int(np.bitwise_or.reduce(np.asarray(status, dtype=np.int64).ravel(), initial=0))
    names = [n for n, v in globals().items() if n.isupper() and isinstance(v, int) and v in _MESSAGES and s & v]
    return f"{s} ({' | '.join(names) if names else 'ok'})"


def raise_for_status(status, *, ignore: int = INFO_FLAGS) -> None:
    """Raise :class:`StatusError` if any flag outside ``ignore`` is set in ``status``.

    Args:
      status: int array of flags, any shape (a batch is OR-reduced).
      ignore: bit mask of flags that are informational; default ignores masked measurements and
        estimator fall-backs.
    """
    s = int(np.bitwise_or.reduce(np.asarray(status, dtype=np.int64).ravel(), initial=0))
    bad = s & ~ignore
    if bad:
        raise StatusError("; ".join(status_messages(bad)))
