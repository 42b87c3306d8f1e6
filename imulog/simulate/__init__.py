"""Synthetic trials with ground truth, written in the raw export formats a lab would have.

>>> from imulog.simulate import simulate
>>> sim = simulate("r2g", subject=0, trial=0, seed=0, repetitions=2, opening_static_s=5.0)
>>> sim.recording.imus[0].name, sim.recording.markers[0].labels
('wrist', ['O', 'X', 'Y', 'A'])
>>> sorted(set(sim.truth.phases.labels))
['lift', 'reach', 'return_bottle', 'return_hand']

See docs/simulate.md for the models and every parameter's source.
"""

from imulog.simulate.core import SimulatedTrial, parameter_names, simulate
from imulog.simulate.files import simulate_to_folder, write_trial_files
from imulog.simulate.protocols import PROTOCOL_NAMES
from imulog.simulate.truth import GroundTruth, load_truth, save_truth

__all__ = [
    "PROTOCOL_NAMES",
    "GroundTruth",
    "SimulatedTrial",
    "load_truth",
    "parameter_names",
    "save_truth",
    "simulate",
    "simulate_to_folder",
    "write_trial_files",
]
