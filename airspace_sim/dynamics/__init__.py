"""Jump-Markov aircraft models (paper §II): transition matrices, noise, mode chain, presets
and a Markov-switching truth generator."""

from airspace_sim.dynamics.markov import (
    transition_matrix_from_sojourn,
    validate_transition_matrix,
)
from airspace_sim.dynamics.models import (
    constant_velocity,
    measurement_noise,
    paper_process_noise,
    position_measurement_matrix,
    transition,
    white_noise_acceleration,
)
from airspace_sim.dynamics.presets import Preset
from airspace_sim.dynamics.presets import get as get_preset
from airspace_sim.dynamics.truth import Trajectories, simulate

__all__ = [
    "Preset",
    "Trajectories",
    "constant_velocity",
    "get_preset",
    "measurement_noise",
    "paper_process_noise",
    "position_measurement_matrix",
    "simulate",
    "transition",
    "transition_matrix_from_sojourn",
    "validate_transition_matrix",
    "white_noise_acceleration",
]
