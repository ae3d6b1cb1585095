"""Generate tests/data/sun_reference.json: sun positions from an INDEPENDENT implementation.

The reference is pvlib-python's NREL SPA (``pvlib.solarposition.spa_python``, numpy path), not arshadow's
code, so tests/test_sun.py compares two implementations of the same published algorithm; the SPA report's
own worked example is checked separately against the report's printed numbers.

The set covers latitudes -70..70 (every 10 deg, plus +-66.56 polar circles), longitudes all round the
globe, all seasons (equinoxes, solstices and other days), sunrise and sunset (pvlib's rise/set times),
polar day (midnight sun) and polar night, random instants 1950..2050, observer elevations 0..4000 m and
local UTC offsets (the ISO strings carry offsets; pvlib is fed the same instants in UTC).

Run (needs pvlib; only to regenerate -- the tests read the JSON)::

    pip install pvlib
    python tests/data/make_sun_reference.py

Output rows: ``time`` (ISO 8601 with offset), ``lat``, ``lon`` (east +), ``elevation`` (m),
``pressure_mbar``, ``temperature_c``, ``delta_t`` (s), ``zenith`` (geometric topocentric), ``apparent_zenith``,
``azimuth`` (clockwise from north), ``tag`` (what the row exercises).
"""

from __future__ import annotations

import json
import sys
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pandas as pd
import pvlib

OUT = Path(__file__).with_name("sun_reference.json")


def _row(t_local: datetime, lat, lon, elev, tag, rng):
    pressure = float(np.round(1013.25 * (1 - 2.25577e-5 * elev) ** 5.25588 + rng.normal(0, 5), 2))
    temp = float(np.round(rng.uniform(-20, 35), 1))
    t_utc = pd.Timestamp(t_local.astimezone(UTC))
    delta_t = float(np.round(pvlib.spa.calculate_deltat(t_utc.year, t_utc.month), 3))
    df = pvlib.solarposition.spa_python(
        pd.DatetimeIndex([t_utc]),
        lat,
        lon,
        altitude=elev,
        pressure=pressure * 100.0,
        temperature=temp,
        delta_t=delta_t,
        how="numpy",
    )
    return {
        "time": t_local.isoformat(),
        "lat": lat,
        "lon": lon,
        "elevation": elev,
        "pressure_mbar": pressure,
        "temperature_c": temp,
        "delta_t": delta_t,
        "zenith": float(df["zenith"].iloc[0]),
        "apparent_zenith": float(df["apparent_zenith"].iloc[0]),
        "azimuth": float(df["azimuth"].iloc[0]),
        "tag": tag,
    }


def main() -> int:
    rng = np.random.default_rng(20040101)
    rows = []
    lats = [float(x) for x in range(-70, 71, 10)] + [-66.56, 66.56]
    seasons = [(3, 20), (6, 21), (9, 23), (12, 21), (2, 5), (5, 10), (8, 15), (11, 5)]
    for lat in lats:
        lon = float(np.round(rng.uniform(-180, 180), 4))
        off = timezone(timedelta(hours=int(np.clip(np.round(lon / 15), -12, 14))))
        for month, day in seasons:
            year = int(rng.integers(1990, 2040))
            for hour in (0, 3, 6, 9, 12, 15, 18, 21):
                t = datetime(year, month, day, hour, int(rng.integers(0, 60)), int(rng.integers(0, 60)), tzinfo=off)
                rows.append(_row(t, lat, lon, 0.0, f"season m{month:02d}", rng))
        # sunrise / sunset on a few days (where the sun rises and sets)
        for month, day in ((3, 20), (6, 21), (9, 23), (12, 21), (1, 15), (7, 15)):
            day_utc = pd.DatetimeIndex([pd.Timestamp(2021, month, day, 12, tz="UTC") - pd.Timedelta(hours=lon / 15)])
            rst = pvlib.solarposition.sun_rise_set_transit_spa(day_utc, lat, lon)
            for key in ("sunrise", "sunset"):
                ts = rst[key].iloc[0]
                if pd.isna(ts):
                    continue
                t = ts.floor("s").to_pydatetime().astimezone(off)
                for dmin in (-20, 0, 20):
                    rows.append(_row(t + timedelta(minutes=dmin), lat, lon, 0.0, f"{key}{dmin:+d}min", rng))
    # polar day (midnight sun) and polar night, both hemispheres, every 2 hours
    for lat, month, day, tag in (
        (70.0, 6, 21, "polar day"),
        (-70.0, 12, 21, "polar day"),
        (75.0, 6, 1, "polar day"),
        (70.0, 12, 21, "polar night"),
        (-70.0, 6, 21, "polar night"),
        (78.2, 12, 1, "polar night"),
        (-78.2, 6, 1, "polar night"),
    ):
        lon = float(np.round(rng.uniform(-180, 180), 4))
        for hour in range(0, 24, 2):
            t = datetime(2022, month, day, hour, 0, 0, tzinfo=UTC)
            rows.append(_row(t, lat, lon, 0.0, tag, rng))
    # random instants, places, elevations and offsets
    for _ in range(150):
        lat = float(np.round(rng.uniform(-70, 70), 5))
        lon = float(np.round(rng.uniform(-180, 180), 5))
        elev = float(np.round(rng.choice([0.0, rng.uniform(0, 4000)]), 2))
        off = timezone(timedelta(minutes=int(rng.integers(-12 * 4, 14 * 4)) * 15))
        t = datetime(1950, 1, 1, tzinfo=UTC) + timedelta(seconds=float(rng.uniform(0, 100 * 365.25 * 86400)))
        t = t.replace(microsecond=0).astimezone(off)
        rows.append(_row(t, lat, lon, elev, "random", rng))

    meta = {
        "generator": "tests/data/make_sun_reference.py",
        "reference": f"pvlib {pvlib.__version__} solarposition.spa_python (NREL SPA, numpy)",
        "numpy": np.__version__,
        "python": sys.version.split()[0],
        "n": len(rows),
    }
    OUT.write_text(json.dumps({"meta": meta, "rows": rows}, indent=0) + "\n")
    print(f"wrote {len(rows)} rows to {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
