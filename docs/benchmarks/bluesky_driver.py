"""BlueSky 1.1.1 driven from a script: our planar traffic onto its sphere, and back.

Imported by ``bluesky_rings.py`` and ``bluesky_scale.py`` when they re-run themselves in
BlueSky's venv (``--side bluesky``); it imports ``bluesky`` only inside its functions, so
the project's venv can import it too. Conventions:

- positions: our metres (east, north) on BlueSky's sphere (R = 6371 km) centred on 0°N 0°E,
  converted with the flat-earth formula BlueSky's resolution uses (:func:`latlon`,
  :func:`metres`);
- aircraft: OpenAP B744 at FL200, CAS set for the requested TAS, heading converted from
  ours (radians CCW from east) to compass degrees, one route waypoint (``ADDWPT``) at the
  destination so that an aircraft resumes its route after a resolution (:func:`create`);
- conflict detection on true states (``ASAS ON``: BlueSky's state-based detection, every
  ``asas_dt`` = 1 s of simulated time), resolution MVP or none (:func:`configure_asas`).
"""

from __future__ import annotations

import json
import math

import numpy as np

EARTH = 6371000.0  # m, BlueSky's flat-earth radius


def latlon(p):
    """p (n, 2) m east/north -> (lat (n,), lon (n,)) degrees."""
    lat = np.degrees(p[:, 1] / EARTH)
    return lat, np.degrees(p[:, 0] / (EARTH * np.cos(np.radians(lat))))


def metres(lat, lon):
    """lat, lon (n,) degrees -> (n, 2) m east/north (inverse of :func:`latlon`)."""
    return np.stack([EARTH * np.radians(lon) * np.cos(np.radians(lat)), EARTH * np.radians(lat)], 1)


def reset(dt):
    """Start BlueSky (detached, once per process) or reset it; simulation step ``dt`` s."""
    import bluesky as bs

    if bs.traf is None:
        bs.init(mode="sim", detached=True)
    bs.sim.reset()
    bs.stack.stack(f"DT {dt}")


def create(ids, start, heading, dest, speed):
    """Create aircraft ``ids`` (n,) at ``start`` (n, 2) m, ``heading`` (n,) rad CCW from
    east, TAS ``speed`` m/s (scalar or (n,)), each routed to ``dest`` (n, 2) m."""
    import bluesky as bs
    from bluesky.tools import aero

    alt = 20000 * aero.ft
    tas = np.broadcast_to(np.asarray(speed, dtype=float), (len(ids),))
    cas = [float(aero.tas2cas(v, alt)) for v in tas]
    lat, lon = latlon(np.asarray(start, dtype=float))
    dlat, dlon = latlon(np.asarray(dest, dtype=float))
    for i, acid in enumerate(ids):
        hdg = (90.0 - math.degrees(heading[i])) % 360.0  # compass, clockwise from north
        bs.traf.cre(
            acid=acid, actype="B744", aclat=lat[i], aclon=lon[i], achdg=hdg, acalt=alt, acspd=cas[i]
        )
        bs.stack.stack(f"ADDWPT {acid} {dlat[i]:.8f} {dlon[i]:.8f}")


def configure_asas(r_safe, lookahead, margin, reso="MVP", hdg_only=False, cd="ON"):
    """Detection ``cd`` (``ON`` = BlueSky's first method, state-based in numpy;
    ``CSTATEBASED`` its C++ one) with protected zone ``r_safe`` m and look-ahead s;
    resolution ``reso`` (``MVP`` or ``OFF``) with factor ``1 + margin``, heading only if
    ``hdg_only``. Stacked: processed at the next ``bs.sim.step()``."""
    import bluesky as bs
    from bluesky.tools import aero

    cmds = [f"ASAS {cd}", f"RESO {reso}", f"ZONER {r_safe / aero.nm:.6f}", f"DTLOOK {lookahead}"]
    if reso != "OFF":
        cmds.append(f"RFACH {1 + margin}")
        if hdg_only:
            cmds.append("RMETHH HDG")
    for cmd in cmds:
        bs.stack.stack(cmd)


def emitter(rows: list, out: str | None):
    """A function that keeps a result row in ``rows``, prints it as one JSON line and, with
    ``out``, appends the line to that file (results survive an interrupted run)."""

    def emit(row: dict) -> None:
        rows.append(row)
        line = json.dumps(row)
        print(line, flush=True)
        if out:
            with open(out, "a") as f:
                f.write(line + "\n")

    return emit
