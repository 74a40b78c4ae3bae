"""``jaxnav monitor``: station velocities with coloured noise on daily files, or S1 on simulated stations.

* ``jaxnav monitor FILES... --out DIR``: each file (NGL ``.tenv3``, SIO ``.neu``, ``.col`` table,
  EarthScope/PBO ``.pos``) is a station: outlier screening, trajectory model (offset, rate,
  annual, semi-annual, steps given by ``--step`` and ``--steps-file`` or detected, post-seismic
  terms, ``--poly-degree``) with white + flicker (+ random-walk) noise fitted by maximum
  likelihood, velocities and their uncertainties, one figure per station
  (:func:`jaxnav.experiments.velocities.run_monitor_velocities`). ``--s1`` adds S1's adaptive-filter
  forecasts and statistics of the same files (:func:`jaxnav.experiments.s1.run_monitor_files`).
* ``jaxnav monitor --simulate --out DIR``: the S1 experiment on simulated stations, S1's
  Tables 1-6 (:func:`jaxnav.experiments.s1.run_monitor_simulation`).

Both write ``monitor.json`` and PNG figures to ``--out``.
"""

from __future__ import annotations

import shlex

from jaxnav.cli._common import MAX_SEEDS, UsageError, float_range, input_file, int_range, prepare_out

#: steps detected per station by default (each must beat the BIC penalty)
DETECT_DEFAULT = 5


def register(subparsers):
    """Add the ``monitor`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "monitor",
        help="daily station files (.tenv3, .neu, .col, PBO .pos) -> velocities "
        "with coloured-noise uncertainties (and, with --s1, S1's adaptive "
        "forecasts); or --simulate (S1 on simulated stations)",
    )
    p.add_argument("files", nargs="*", help="daily series, one station per file")
    p.add_argument("--out", default="out/monitor", help="output folder; default out/monitor")
    p.add_argument(
        "--step",
        action="append",
        default=[],
        metavar="STATION:DATE",
        help="a known step (antenna change) at DATE (YYYY-MM-DD or decimal year) for STATION; repeat for more",
    )
    p.add_argument(
        "--steps-file",
        action="append",
        default=[],
        metavar="FILE",
        help="known steps, one a line: STATION DATE KIND [log:TAU|exp:TAU|log:estimate ...] with KIND "
        "equipment, earthquake or unknown, post-seismic terms (TAU days) after earthquakes only; "
        "NGL steps.txt lines are read too (docs/guide/stations.md); repeat for more files",
    )
    p.add_argument(
        "--postseismic",
        action="append",
        default=[],
        metavar="STATION:DATE:FORM:TAU",
        help="an earthquake at DATE for STATION: a step and a post-seismic term, FORM log "
        "(a log(1 + dt/tau)) or exp (a (1 - exp(-dt/tau))), TAU its time constant in days or "
        "'estimate'; repeat for more terms or stations",
    )
    p.add_argument(
        "--poly-degree",
        type=int_range(1, 4),
        default=1,
        help="degree of the polynomial in time, 1 .. 4; default 1 (offset and rate); 2 adds an "
        "acceleration; the rate is the velocity at the reference epoch (mid-span)",
    )
    p.add_argument(
        "--detect-steps",
        type=int_range(0, 10),
        default=DETECT_DEFAULT,
        help="detect up to this many further steps per station (added one at a time while the "
        f"likelihood gain beats the BIC penalty), 0 .. 10; default {DETECT_DEFAULT}",
    )
    p.add_argument("--no-detect-steps", action="store_true", help="no step detection (same as --detect-steps 0)")
    p.add_argument(
        "--extra-period",
        type=float_range(1.0),
        action="append",
        default=[],
        metavar="DAYS",
        help="a further periodic term of DAYS days (e.g. 351.6, the GPS draconitic year), >= 1; repeat for more",
    )
    p.add_argument(
        "--kappa",
        default="-1",
        help="spectral index of the power-law noise in (-2, 0) (-1 flicker, the default) or 'estimate'",
    )
    p.add_argument("--no-random-walk", action="store_true", help="white + power-law noise only")
    p.add_argument("--ml", action="store_true", help="plain maximum likelihood instead of REML (Hector's default)")
    p.add_argument("--no-screen", action="store_true", help="no outlier screening")
    p.add_argument(
        "--sigma-factor",
        type=float_range(1.0, lo_open=True),
        default=5.0,
        help="reject days whose formal sigma exceeds this x the median, > 1; default 5",
    )
    p.add_argument(
        "--residual-k",
        type=float_range(0.0, lo_open=True),
        default=5.0,
        help="reject values beyond this x the robust residual scale, > 0; default 5",
    )
    p.add_argument("--s1", action="store_true", help="also run S1's adaptive-filter forecasts on the files")
    p.add_argument("--simulate", action="store_true", help="the S1 experiment on simulated 1 Hz stations")
    p.add_argument(
        "--period", type=int_range(1), default=365, help="epochs per statistics period for --s1, >= 1; default 365"
    )
    p.add_argument("--robust", action="store_true", help="add the robust filters (IGG-III, Yang) to S1")
    p.add_argument("--periods", type=int_range(1, MAX_SEEDS), default=60, help="simulated periods, >= 1; default 60")
    p.add_argument("--stations", type=int_range(1, 1000), default=2, help="simulated stations, 1 .. 1000; default 2")
    p.add_argument(
        "--epochs",
        type=int_range(2, 10**6),
        default=3600,
        help="epochs per simulated period, 2 .. 1e6; default 3600 (1 h)",
    )
    p.add_argument(
        "--gross", type=float_range(0.0, 1.0), default=0.0, help="share of 10-sigma gross errors in [0, 1] (simulation)"
    )
    p.add_argument(
        "--seed", type=int_range(0, 2**32 - 1), default=2017, help="PRNG seed of the simulation (0 .. 2^32-1)"
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return p


def _epoch(text: str, option: str = "--step") -> float:
    """YYYY-MM-DD or a decimal year -> s since J2000 (:func:`jaxnav.io.date_to_epoch`; UsageError otherwise)."""
    from jaxnav.io import date_to_epoch

    try:
        return date_to_epoch(text)
    except ValueError as exc:
        raise UsageError(f"{option}: {exc}") from None


def _steps(items) -> dict:
    out = {}
    for it in items:
        if ":" not in it:
            raise UsageError(f"--step expects STATION:DATE, got {it!r}")
        st, date = it.split(":", 1)
        out.setdefault(st.strip().upper(), []).append(_epoch(date.strip()))
    return out


def _postseismic(items) -> list:
    """--postseismic STATION:DATE:FORM:TAU values -> :class:`jaxnav.io.KnownStep` (earthquakes)."""
    from jaxnav.io import KnownStep, parse_postseismic

    out = []
    for it in items:
        parts = it.split(":")
        if len(parts) != 4 or not parts[0].strip():
            raise UsageError(
                f"--postseismic expects STATION:DATE:FORM:TAU (e.g. ABCD:2011-03-11:log:30 or "
                f"ABCD:2011-03-11:log:estimate), got {it!r}"
            )
        try:
            term = parse_postseismic(f"{parts[2]}:{parts[3]}")
        except ValueError as exc:
            raise UsageError(f"--postseismic {it}: {exc}") from None
        out.append(
            KnownStep(
                parts[0].strip().upper(),
                _epoch(parts[1].strip(), "--postseismic"),
                "earthquake",
                (term,),
                f"--postseismic {it}",
            )
        )
    return out


def _kappa(text: str):
    if text.strip().lower() in ("estimate", "estimated", "free"):
        return None
    try:
        k = float(text)
    except ValueError:
        raise UsageError(f"--kappa: expected a number in (-2, 0) or 'estimate', got {text!r}") from None
    if not -2.0 < k < 0.0:
        raise UsageError(f"--kappa {text}: the spectral index must lie in (-2, 0) (the random walk is its own term)")
    return k


def run(args) -> int:
    """Process the files (or simulate), print the results, write monitor.json and figures into ``--out``."""
    from jaxnav.experiments.s1 import run_monitor_simulation
    from jaxnav.experiments.velocities import run_monitor_velocities

    if not args.simulate and not args.files:
        raise UsageError("give daily series files (.tenv3, .neu, .col, .pos) or --simulate")
    if args.simulate and args.files:
        raise UsageError("give either daily series files or --simulate, not both")
    files = [input_file(f, "FILES") for f in args.files]
    steps, kappa = _steps(args.step), _kappa(args.kappa)
    known = _postseismic(args.postseismic)
    steps_files = [input_file(f, "--steps-file") for f in args.steps_file]
    if steps_files or known:
        from jaxnav.io import read_steps_file

        for f in steps_files:
            known += read_steps_file(f)
    out = prepare_out(args.out)
    args._json_outputs = ("monitor.json",)  # main adds the provenance block to it
    if args.simulate:
        res = run_monitor_simulation(
            out,
            periods=args.periods,
            stations=args.stations,
            epochs=args.epochs,
            robust=args.robust,
            gross=args.gross,
            seed=args.seed,
            progress=not args.no_progress,
        )
        print(res["text"])
        print(
            f"\nwrote {out / 'monitor.json'}, {out / 's1_statistics.png'}, {out / 's1_period.png'} "
            f"({res['wall_time_s']:.1f} s)"
        )
        return 0
    detect = 0 if args.no_detect_steps else args.detect_steps
    res = run_monitor_velocities(
        files,
        out,
        steps=steps,
        detect=detect,
        kappa=kappa,
        random_walk=not args.no_random_walk,
        reml=not args.ml,
        screen=not args.no_screen,
        sigma_factor=args.sigma_factor,
        residual_k=args.residual_k,
        s1=args.s1,
        period=args.period,
        robust=args.robust,
        command=shlex.join(["jaxnav", *args._argv]),
        periods_days=tuple(args.extra_period),
        known_steps=known,
        steps_files=steps_files,
        poly_degree=args.poly_degree,
    )
    print(res["text"])
    print(f"wrote {out / 'monitor.json'} and {len(args.files)} figure(s) in {out} ({res['wall_time_s']:.1f} s)")
    return 0
