"""``visloc sim``: closed-loop simulation scenarios on the non-linear model."""

from __future__ import annotations

import argparse
import json
import math
import sys

_ROWS = (
    ("settling_time_s", "settling time (5 % band)", "s"),
    ("overshoot_pct", "overshoot", "%"),
    ("position_rms_m", "position RMS from the set point", "m"),
    ("height_dip_m", "height dip after the step / push", "m"),
    ("estimate_rms_m", "estimate error RMS (position)", "m"),
    ("max_tilt_deg", "largest roll / pitch", "deg"),
    ("saturated_fraction", "control steps with a saturated motor", ""),
    ("linear_settling_time_s", "linear model: settling time", "s"),
    ("linear_overshoot_pct", "linear model: overshoot", "%"),
    ("linear_height_dip_m", "linear model: height dip", "m"),
    ("camera_frames", "bottom-camera frames", ""),
    ("vision_fixes", "frames with a marker-map fix", ""),
    ("realtime_factor", "simulated seconds per wall-clock second", ""),
)


def sim(args: argparse.Namespace) -> int:
    """``visloc sim SCENARIO``: fly a scenario (:data:`visloc.sim.SCENARIOS`) in closed loop;
    print the metrics (or ``--json``), optionally write ``--out`` CSV, ``--plot`` PNG and
    ``--rerun`` recording. Exit 0 when the run settled or completed, 1 when it crashed or
    diverged, 130 when Ctrl-C stopped it (the outputs then cover the steps flown so far).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``visloc sim`` command line (:func:`visloc.cli.build_parser`).

    Returns
    -------
    int
        Exit status: 0 settled or completed, 1 crashed or diverged, 130 interrupted.
    """
    from visloc.sim import (
        SimStatus,
        figure8_scenario,
        get_scenario,
        simulate,
        square_scenario,
        step_scenario,
    )
    from visloc.sim.output import save_plot, save_rerun, write_csv

    if args.scenario == "step":  # a side step of --distance m: smooth with feed-forward, or --plain
        scenario = step_scenario(args.distance, smooth=not args.plain)
    elif args.scenario == "square":
        scenario = square_scenario(args.side, speed=args.speed, vision=args.vision)
    elif args.scenario == "figure8":
        scenario = figure8_scenario(args.side, speed=args.speed, vision=args.vision)
    else:
        scenario = get_scenario(args.scenario)
    for option, suffix in (("out", ".csv"), ("plot", ".png"), ("rerun", ".rrd")):
        value = getattr(args, option)
        if value and not value.lower().endswith(suffix):
            raise ValueError(f"--{option}: expected a {suffix} file, got {value!r}")
    seconds = args.seconds if args.seconds is not None else scenario.seconds
    show = not args.json and not args.quiet and seconds >= 10 and sys.stderr.isatty()
    bar = None
    if show:
        from tqdm import tqdm

        bar = tqdm(total=round(seconds), unit="sim s", desc=f"visloc sim {scenario.name}")
    try:
        result = simulate(scenario, sigma=args.sigma, seed=args.seed, seconds=args.seconds,
                          camera_rate=args.camera_rate, motor_lag=args.motor_lag, warmup=args.warmup,
                          redetect_every=args.redetect_every,
                          max_tilt=math.inf if args.unbounded else 0.3,
                          progress=(lambda _t: bar.update(1)) if bar is not None else None)
    finally:
        if bar is not None:
            bar.close()
    written = []
    if args.out:
        written.append(str(write_csv(result, args.out)))
    if args.plot:
        written.append(str(save_plot(result, args.plot)))
    if args.rerun:
        written.append(str(save_rerun(result, args.rerun)))
    if args.json:
        out = result.to_dict()
        out["written"] = written
        print(json.dumps(out, indent=1))
    else:
        print(f"visloc sim {result.scenario}: {scenario.description}")
        print(f"status: {result.status.value} ({result.reason})")
        for key, label, unit in _ROWS:
            value = result.metrics.get(key)
            if key not in result.metrics:
                continue
            text = "n/a" if value is None else (f"{value:.4g}" if isinstance(value, float) else str(value))
            print(f"  {label:<42} {text} {unit}".rstrip())
        for path in written:
            print(f"wrote {path}")
    if result.status is SimStatus.INTERRUPTED:
        print("visloc: interrupted; results written so far are kept", file=sys.stderr)
        return 130
    return 0 if result.status in (SimStatus.SETTLED, SimStatus.COMPLETED) else 1
