"""``jaxnav allan IMU_FILE``: IMU noise densities from a static recording (Allan variance), with a
figure per sensor and a ``[noise]`` section ready for a ``jaxnav ins`` config
(:func:`jaxnav.experiments.allan.run_allan`)."""

from __future__ import annotations

import logging

from jaxnav.cli._common import UsageError, float_range, input_file, int_range, prepare_out


def register(subparsers):
    """Add the ``allan`` subcommand; returns its parser."""
    p = subparsers.add_parser(
        "allan",
        help="IMU noise from a static recording: Allan deviation per axis, fitted angle/velocity random "
        "walk, bias instability and rate random walk with uncertainties, figures and a [noise] TOML",
    )
    p.add_argument("imu_file", help="the static IMU log")
    p.add_argument(
        "--format",
        default="rtklib-csv",
        choices=("rtklib-csv", "kf-gins", "csv"),
        help="IMU file format, as [imu] format of `jaxnav ins` (default rtklib-csv)",
    )
    p.add_argument(
        "--tag",
        default=None,
        help="rtklib-csv: the RTKLIB time-tag file (default: IMU_FILE.tag if it exists, else the counter column in ms)",
    )
    p.add_argument(
        "--columns",
        default=None,
        metavar="MAP",
        help="csv: column map, e.g. t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6 (indices or header names)",
    )
    p.add_argument("--units", default=None, metavar="MAP", help="csv: units, e.g. t=s,gyro=deg/s,accel=g")
    p.add_argument("--delimiter", default=",", help="csv: field separator, one character or 'whitespace'")
    p.add_argument("--gps-week", type=int_range(0, 5000), default=None, help="kf-gins: GPS week of the start")
    p.add_argument(
        "--start",
        type=float_range(0.0),
        default=None,
        metavar="S",
        help="use the log from this many seconds after its first sample",
    )
    p.add_argument(
        "--end",
        type=float_range(0.0, lo_open=True),
        default=None,
        metavar="S",
        help="... up to this many seconds after its first sample",
    )
    p.add_argument(
        "--tau-min",
        type=float_range(0.0, lo_open=True),
        default=None,
        metavar="S",
        help="fit only taus >= this (e.g. above an anti-alias filter's time constant)",
    )
    p.add_argument(
        "--tau-max", type=float_range(0.0, lo_open=True), default=None, metavar="S", help="fit only taus <= this"
    )
    p.add_argument("--out", default="out/allan", help="output folder; default out/allan")
    return p


def _map(text, option, ints: bool):
    """``a=1,b=x`` -> {"a": 1, "b": "x"} (values that are integers become ints when ``ints``)."""
    out = {}
    for part in str(text).split(","):
        if not part.strip():
            continue
        k, sep, v = part.partition("=")
        if not sep or not k.strip() or not v.strip():
            raise UsageError(f"{option}: expected KEY=VALUE pairs separated by commas, got {part!r}")
        v = v.strip()
        out[k.strip()] = int(v) if ints and v.isdigit() else v
    return out


def run(args) -> int:
    """Check the options and the file, read it, fit, write the outputs, print the summary."""
    import pathlib

    from jaxnav.experiments.allan import format_allan, run_allan
    from jaxnav.io import read_imu

    path = input_file(args.imu_file, "IMU_FILE")
    if args.format != "csv" and (args.columns or args.units):
        raise UsageError("--columns/--units are only used with --format csv")
    if args.format == "csv" and not args.columns:
        raise UsageError("--format csv needs --columns (e.g. t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6)")
    if args.tag and args.format != "rtklib-csv":
        raise UsageError("--tag is only used with --format rtklib-csv")
    if args.start is not None and args.end is not None and args.end <= args.start:
        raise UsageError(f"--end {args.end:g} must be after --start {args.start:g}")
    if args.tau_min is not None and args.tau_max is not None and args.tau_max <= args.tau_min:
        raise UsageError(f"--tau-max {args.tau_max:g} must be above --tau-min {args.tau_min:g}")
    tag = args.tag
    if args.format == "rtklib-csv" and tag is None and pathlib.Path(str(path) + ".tag").is_file():
        tag = str(path) + ".tag"
    if tag is not None:
        tag = input_file(tag, "--tag")
    delim = None if args.delimiter == "whitespace" else args.delimiter
    if delim is not None and len(delim) != 1:
        raise UsageError(f"--delimiter must be one character or 'whitespace', got {args.delimiter!r}")
    prepare_out(args.out)
    columns = _map(args.columns, "--columns", True) if args.columns else None
    units_map = _map(args.units, "--units", False) if args.units else None
    log = logging.getLogger("jaxnav")
    log.info("reading %s (%s)", path, args.format)
    imu = read_imu(
        path,
        args.format,
        tag=tag,
        t_start=None if tag else 0.0,
        columns=columns,
        units=units_map,
        delimiter=delim,
        gps_week=args.gps_week,
    )
    tau_range = None
    if args.tau_min is not None or args.tau_max is not None:
        tau_range = (args.tau_min or 0.0, args.tau_max or float("inf"))
    summary = run_allan(imu, args.out, source=path.name, start_s=args.start, end_s=args.end, tau_range=tau_range)
    print(format_allan(summary))
    print(f"wrote allan_gyro.png, allan_accel.png, noise.toml and results.json into {args.out}")
    return 0
