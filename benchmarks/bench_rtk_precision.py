"""RTK point precision with correlated epochs (issue 19): claimed vs actual scatter on real static files.

A script, not a test (the small checks are in tests/survey/test_rtk_precision.py). Prints a
markdown report (copied into benchmarks/RESULTS.md by hand):

    .venv/bin/python benchmarks/bench_rtk_precision.py [--mc 200]

1. Real static files of ../shared/data, cut into points of 2 min / 1 min / 30 s (epochs thinned
   to 2 s as in S2, and 2 min at 1 Hz): per component (GK x north, y east, ellipsoidal H) the
   actual scatter of the point means (ddof 1) against the rms claimed sigma, ``acf_ess_segment``
   and the independent-epoch sigma (S2 eq. (19) on the raw epochs).
2. S2's "4x better internal precision" of the filtered result: eq. (19) conventional / eq. (19)
   filtered (what S2 reports) against the actual scatter of the plain means / of the filtered means
   (what the data show), forward filter and with the RTS pass.
3. The regime of the issue's u-blox file (lag-1 autocorrelation 0.96-0.97, not available here):
   simulated 42-min static halves (1260 epochs at 2 s, white + AR(1) phi = 0.97 per 2 s), cut
   into 21 two-minute points; distribution of actual / claimed over Monte Carlo series.
4. The static/moving test on the real static file followed by the real car drive.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
DATA = ROOT.parent / "shared" / "data"

import jax

jax.config.update("jax_enable_x64", True)

from jaxnav.io import read_pos
from jaxnav.survey import motion_segments, pack_points, point_sigmas, process_points, windows_from_pos

FILES = {
    "Nagoya rooftop (MatRTKLIB, real, 5 min 1 Hz)": (DATA / "rtk_pos_matrtklib/static/rover_rtk.pos", 138.0),
    "Spirent static rover (INSTINCT, simulated signals, 10 min 1 Hz)": (
        DATA / "rtk_pos_instinct_simulated/Rover-static-2km-east_RTK_GPS-GAL_Forward_Continuous.pos",
        9.0,
    ),
}


def points(path, step, window, lon0_deg):
    w = windows_from_pos(read_pos(path), step=step, window=window, min_epochs=window // 2)
    names, ser = pack_points(w["point"], w["t"], w["lat"], w["lon"], w["H"], w["sigma"], mask=w["mask"])
    grid = np.zeros(ser.mask.shape, np.int64)
    seg = []
    for i, n in enumerate(names):
        gi = w["grid"][w["point"] == n]
        grid[i, : gi.size], grid[i, gi.size :] = gi, gi[-1]
        seg.append(w["segment"][w["point"] == n][0])
    return names, ser, grid, np.array(seg), np.radians(lon0_deg)


def fmt3(v, scale=1e3, d=3):
    return " / ".join(f"{x * scale:.{d}f}" for x in v)


def real_files():
    rows, s2rows = [], []
    for label, (path, lon0) in FILES.items():
        for step, window, what in (
            (2.0, 60, "2 min at 2 s"),
            (1.0, 120, "2 min at 1 s"),
            (2.0, 30, "1 min at 2 s"),
            (2.0, 15, "30 s at 2 s"),
        ):
            names, ser, grid, seg, l0 = points(path, step, window, lon0)
            n_all = len(names)
            keep = np.asarray(ser.mask).sum(1) >= 2  # points with fewer than 2 fixed epochs are left out
            names, grid, seg = names[keep], grid[keep], seg[keep]
            ser = type(ser)(*[np.asarray(a)[keep] for a in ser])
            outs = {}
            for smoother in (False, True):
                outs[smoother] = res = process_points(ser, lon0=l0, smoother=smoother)
            res = outs[False]
            z, mask = np.asarray(res.gk), np.asarray(ser.mask)
            ps = point_sigmas(z, mask, grid, seg)
            means = np.array([z[p][mask[p]].mean(0) for p in range(len(names))])
            actual = means.std(0, ddof=1)
            claimed = np.sqrt(np.mean(ps.sigma**2, 0))
            naive = np.sqrt(np.mean(ps.sigma_naive**2, 0))
            pooled = np.sqrt(np.mean((actual / claimed) ** 2))
            kept = f"{len(names)}{'' if n_all == len(names) else f' of {n_all}'}"
            counts = ", ".join(str(int(n)) for n in np.asarray(res.n))
            rows.append(
                f"| {label} | {what} | {kept} ({counts}) | "
                f"{fmt3(actual)} | {fmt3(claimed)} | {fmt3(actual / claimed, 1, 2)} ({pooled:.2f}) | "
                f"{fmt3(naive)} | {fmt3(actual / naive, 1, 1)} | {fmt3(np.mean(ps.lag1, 0), 1, 2)} |"
            )
            if what == "2 min at 2 s":
                for smoother, r in outs.items():
                    raw = np.asarray(r.raw_xyh)
                    filt = np.asarray(r.xyh)
                    e19_conv = np.sqrt(np.mean(np.asarray(r.raw_precision) ** 2, 0))
                    e19_filt = np.sqrt(np.mean(np.asarray(r.precision) ** 2, 0))
                    sc_raw, sc_filt = raw.std(0, ddof=1), filt.std(0, ddof=1)
                    s2rows.append(
                        f"| {label} | {'forward + RTS' if smoother else 'forward filter'} | "
                        f"{fmt3(e19_conv / e19_filt, 1, 2)} | {fmt3(sc_raw)} | {fmt3(sc_filt)} | "
                        f"{fmt3(sc_raw / sc_filt, 1, 2)} | {fmt3(claimed)} |"
                    )
    return rows, s2rows


def simulated(mc, seed=0, n=1260, window=60, phi=0.97, s_ar=4.0e-3, s_white=1.0e-3):
    """White + AR(1) series (one component, repeated in 3 columns with independent draws)."""
    rng = np.random.default_rng(seed)
    ratios, naive_ratios, lag1, truth = [], [], [], []
    P = n // window
    grid = np.tile(np.arange(window), (P, 1)) + window * np.arange(P)[:, None]
    mask = np.ones((P, window), bool)
    seg = np.array(["s"] * P)
    for _ in range(mc):
        e = rng.standard_normal((n + 500, 3)) * s_ar * np.sqrt(1 - phi**2)
        a = np.zeros((n + 500, 3))
        for k in range(1, n + 500):
            a[k] = phi * a[k - 1] + e[k]
        x = a[500:] + rng.standard_normal((n, 3)) * s_white
        z = x.reshape(P, window, 3)
        ps = point_sigmas(z, mask, grid, seg)
        actual = z.mean(1).std(0, ddof=1)
        ratios.append(actual / np.sqrt(np.mean(ps.sigma**2, 0)))
        naive_ratios.append(actual / np.sqrt(np.mean(ps.sigma_naive**2, 0)))
        lag1.append(np.mean(ps.lag1, 0))
        truth.append(np.sqrt(np.mean(z.mean(1) ** 2, 0)) / np.sqrt(np.mean(ps.sigma**2, 0)))
    r, nr, tr = np.concatenate(ratios), np.concatenate(naive_ratios), np.concatenate(truth)
    # the exact sd of a 2-minute mean about the truth for this process (AR(1) + white)
    k = np.arange(1, window)
    g0 = s_ar**2
    exact = np.sqrt((g0 * (1 + 2 * np.sum((1 - k / window) * phi**k)) + s_white**2) / window)
    return r, nr, tr, float(np.mean(lag1)), exact


def slow(mc, q):
    """The limit: an error process slower than the segment (Gauss-Markov tau = 20 min in 42 min)."""
    phi = float(np.exp(-2.0 / 1200.0))
    r, nr, tr, l1, exact = simulated(mc, seed=1, phi=phi)
    print(
        f"\nLimit of the method ({mc} x 3 components; same 21 points, AR(1) 4 mm with tau = 20 min, phi "
        f"{phi:.5f} per 2 s): actual / claimed {q(r)}; against the truth (exact sd {exact * 1e3:.2f} mm) "
        f"truth rms / claimed {q(tr)}: the error common to the 42-min segment is not in the sigma."
    )


def drive_test():
    st = read_pos(FILES["Nagoya rooftop (MatRTKLIB, real, 5 min 1 Hz)"][0])
    dr = read_pos(DATA / "rtk_pos_matrtklib/kinematic/rover_1Hz_rtk.pos")
    t = np.r_[st.t, dr.t - dr.t[0] + st.t[-1] + 1.0]
    seg = motion_segments(t, np.r_[st.lat, dr.lat], np.r_[st.lon, dr.lon])
    ns = st.t.size
    segs = [
        (int((seg.segment == s).sum()), float(t[seg.segment == s][-1] - t[seg.segment == s][0]))
        for s in range(seg.n_segments)
    ]
    return ns, len(t) - ns, int(seg.moving[:ns].sum()), int(seg.moving[ns:].sum()), int(seg.short.sum()), segs


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mc", type=int, default=200, help="Monte Carlo series for part 3")
    ap.add_argument("--only-slow", action="store_true", help="only the slow-error simulation (part 3b)")
    a = ap.parse_args()
    t0 = time.time()
    q = lambda v: f"median {np.median(v):.2f}, 5-95 % {np.percentile(v, 5):.2f}-{np.percentile(v, 95):.2f}"
    if a.only_slow:
        slow(a.mc // 4, q)
        return
    rows, s2rows = real_files()
    print(
        "| file | points of | K points (epochs) | actual scatter x / y / h mm | claimed (acf_ess_segment) | "
        "actual / claimed (pooled) | naive (independent epochs) | actual / naive | lag-1 autocorr. |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    print()
    print(
        "| file (2-minute points, 2 s) | S2 pipeline | eq. (19) conventional / filtered (S2's '4x') | "
        "actual scatter of plain means mm | of filtered means mm | actual improvement | "
        "claimed acf_ess_segment mm |"
    )
    print("|---|---|---|---|---|---|---|")
    print("\n".join(s2rows))
    print()
    r, nr, tr, l1, exact = simulated(a.mc)
    print(
        f"Simulated u-blox regime ({a.mc} x 3 components; 21 two-minute points of one 42-min static half, "
        f"white 1 mm + AR(1) 4 mm phi 0.97 per 2 s; mean estimated lag-1 {l1:.3f}): actual / claimed {q(r)}; "
        f"within a factor 1.5: {np.mean((r > 1 / 1.5) & (r < 1.5)) * 100:.0f} %; actual / naive {q(nr)}. "
        f"Against the truth (rms of the point means about the true position, exact sd {exact * 1e3:.2f} mm): "
        f"truth rms / claimed {q(tr)}."
    )
    slow(a.mc // 4, q)
    ns, nd, ms, md, sh, segs = drive_test()
    print(
        f"\nStatic/moving test (defaults): Nagoya static file ({ns} epochs) followed by the MatRTKLIB car drive "
        f"({nd} epochs): moving {ms} of the static epochs (the last ones within 5 s of the departure), {md} of "
        f"the drive's; {sh} epochs in static runs < 20 s; static segments (epochs, s): {segs}"
    )
    print(f"\n(whole script {time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
