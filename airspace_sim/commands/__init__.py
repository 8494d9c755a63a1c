"""Subcommands of the ``airspace-sim`` CLI, one module each (see :mod:`airspace_sim.cli`)."""
