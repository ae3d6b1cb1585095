"""``arshadow sun``: where the sun is, and where a 1 m pole's shadow falls.

Prints the zenith (geometric and apparent), the azimuth (clockwise from north), the unit direction
towards the sun in east-north-up coordinates and in the world (marker) frame, and the length and compass
bearing of the shadow of a 1 m vertical pole on level ground. ``--json`` prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from datetime import UTC
from typing import Any

DESCRIPTION = """\
Sun position for an instant and a place (NREL SPA by default; [Kolivand-Sun]'s formula with --sun-model paper).
TIME is ISO 8601 with a UTC offset, e.g. 2011-04-22T10:59+08:00 or 2003-10-17T19:30:30Z.
Longitude is east positive. NORTH (--north) is the compass bearing of the world +y axis, degrees clockwise
from true north (0: +y = north, +x = east). "zenith" is geometric (no refraction); "apparent zenith"
includes the SPA's refraction for --pressure and --temperature. The world direction and the pole's shadow
use the geometric sun unless --refraction is given.
"""


# subparsers: the argparse._SubParsersAction cli/__init__.py passes in (a private class, hence Any)
def register(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "sun",
        help="sun zenith/azimuth/direction and a 1 m pole's shadow for a date, time and place",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--lat", type=float, required=True, help="latitude, degrees (north positive), -90..90")
    p.add_argument("--lon", type=float, required=True, help="longitude, degrees (EAST positive), -180..180")
    p.add_argument("--time", required=True, help="ISO 8601 instant WITH a UTC offset, e.g. 2011-04-22T10:59+08:00")
    p.add_argument(
        "--elevation", type=float, default=0.0, metavar="M", help="observer height above sea level, m (default 0)"
    )
    p.add_argument(
        "--north",
        type=float,
        default=0.0,
        metavar="DEG",
        help="compass bearing of the world +y axis, degrees clockwise from true north (default 0)",
    )
    p.add_argument(
        "--sun-model",
        default="spa",
        choices=("spa", "paper", "paper-printed"),
        help="spa = NREL SPA (default, ~0.0003 deg); paper = [Kolivand-Sun]'s formula, corrected (~0.2 deg); "
        "paper-printed = its azimuth exactly as printed (wrong; for comparison)",
    )
    p.add_argument(
        "--pressure",
        type=float,
        default=None,
        metavar="MBAR",
        help="mean local pressure for refraction, mbar (default: standard atmosphere at --elevation)",
    )
    p.add_argument(
        "--temperature",
        type=float,
        default=12.0,
        metavar="C",
        help="mean local temperature for refraction, deg C (default 12)",
    )
    p.add_argument(
        "--delta-t",
        type=float,
        default=None,
        metavar="S",
        help="TT - UT in seconds (default: Espenak & Meeus estimate for the date)",
    )
    p.add_argument(
        "--refraction",
        action="store_true",
        help="use the apparent (refracted) sun for the world direction and the shadow",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def _round(v: Any, nd: int = 9) -> Any:
    if v is None:
        return None
    if isinstance(v, (list, tuple)):
        return [_round(x, nd) for x in v]
    return round(float(v), nd)


def compute(args: argparse.Namespace) -> dict:
    """The JSON object of ``arshadow sun`` for parsed ``args`` (LightError on bad input)."""

    from ..lights.spec import parse_time
    from ..lights.sun import enu_to_world, pole_shadow, sun_light_direction, sun_position

    when = parse_time(args.time, "--time")
    pos = sun_position(
        when,
        args.lat,
        args.lon,
        elevation=args.elevation,
        model=args.sun_model,
        pressure_mbar=args.pressure,
        temperature_c=args.temperature,
        delta_t=args.delta_t,
    )
    world, above = sun_light_direction(pos, args.north, refraction=args.refraction)
    enu = pos.apparent_enu if args.refraction else pos.enu
    shadow = pole_shadow(world, 1.0, args.north) if above else None
    assert pos.when is not None  # sun_position always sets it
    return {
        "time": when.isoformat(),
        "time_utc": pos.when.astimezone(UTC).isoformat(),
        "lat": pos.latitude,
        "lon": pos.longitude,
        "elevation_m": pos.elevation,
        "north_deg": float(args.north),
        "model": pos.model,
        "zenith_deg": _round(pos.zenith_deg),
        "apparent_zenith_deg": _round(pos.apparent_zenith_deg),
        "elevation_deg": _round(90.0 - (pos.apparent_zenith_deg if args.refraction else pos.zenith_deg)),
        "azimuth_deg": _round(pos.azimuth_deg),
        "refraction": bool(args.refraction),
        "enu": _round(list(enu)),
        "world": _round(list(world)),
        "apparent_enu": _round(list(pos.apparent_enu)),
        "apparent_world": _round(list(enu_to_world(pos.apparent_enu, args.north))),
        "above_horizon": bool(above),
        "shadow_length_1m": _round(shadow["length"]) if shadow else None,
        "shadow_bearing_deg": _round(shadow["bearing_deg"]) if shadow else None,
        "shadow_tip_world": _round(shadow["tip_world"]) if shadow else None,
        "declination_deg": _round(pos.declination_deg),
        "hour_angle_deg": _round(pos.hour_angle_deg),
        "pressure_mbar": _round(pos.extra["pressure_mbar"], 3),
        "temperature_c": pos.extra["temperature_c"],
        "delta_t_s": None if math.isnan(pos.extra["delta_t"]) else _round(pos.extra["delta_t"], 3),
    }


def run(args: argparse.Namespace) -> int:
    out = compute(args)
    if args.json:
        json.dump(out, sys.stdout, indent=1, allow_nan=False)
        sys.stdout.write("\n")
        return 0
    f = "{:+.6f}".format
    lines = [
        f"time              {out['time']}  ({out['time_utc']} UTC)",
        f"place             lat {out['lat']:.6f}, lon {out['lon']:.6f} (east +), elevation {out['elevation_m']:g} m",
        f"model             {out['model']}" + ("  (with refraction)" if out["refraction"] else ""),
        f"zenith            {out['zenith_deg']:.5f} deg  (geometric, no refraction)",
        f"apparent zenith   {out['apparent_zenith_deg']:.5f} deg  (refraction at {out['pressure_mbar']:g} mbar, "
        f"{out['temperature_c']:g} C)",
        f"azimuth           {out['azimuth_deg']:.5f} deg  (clockwise from north)",
        f"direction ENU     [{', '.join(f(v) for v in out['enu'])}]  (towards the sun)",
        f"direction world   [{', '.join(f(v) for v in out['world'])}]  (world +y at bearing {out['north_deg']:g} deg)",
    ]
    if out["above_horizon"]:
        lines.append(
            f"1 m pole shadow   length {out['shadow_length_1m']:.4f} m, bearing {out['shadow_bearing_deg']:.3f} deg "
            f"(tip at world x {out['shadow_tip_world'][0]:+.4f}, y {out['shadow_tip_world'][1]:+.4f})"
        )
    else:
        lines.append("1 m pole shadow   none: the sun is below the horizon (it casts no shadow)")
    print("\n".join(lines))
    return 0
