"""Recorded traffic: ADS-B / OpenSky trajectories read, cleaned and projected to a local
metric frame, and replayed in the world.

- :mod:`.flights`: :class:`Flights` / :class:`Flight` (the container every reader returns)
  and :class:`Frame` (the local azimuthal equidistant projection);
- :mod:`.readers`: :func:`read` for OpenSky state vectors and the ``traffic`` library's
  CSV, Parquet and pandas JSON records (``.json``, ``.json.gz``);
- :mod:`.samples`: the OpenSky samples shipped in the ``traffic`` wheel (never copied here);
- :mod:`.autopilot`: the ``"recorded"`` autopilot that flies an aircraft along its recording.

Readers need the ``real`` extra (pyproj, pandas): ``pip install 'airspace-sim[real]'``.
"""

from airspace_sim.recorded.flights import MAX_GAP_S, Flight, Flights, Frame, turn_rates

__all__ = ["MAX_GAP_S", "Flight", "Flights", "Frame", "read", "turn_rates"]


def read(*args, **kwargs):
    """:func:`airspace_sim.recorded.readers.read` (imported on first use: pandas is heavy)."""
    from airspace_sim.recorded.readers import read as _read

    return _read(*args, **kwargs)
