"""Sim-to-real discrepancy workflow (``exohil discrepancy``): calibrate a static model of the
suit to a measured recording, find where simulation and measurement disagree, name the missing
physical effect (hysteresis, creep, saturation, lag, drift), add it and show the gap shrink.

See docs/discrepancy.md. Entry points: :func:`run` (the workflow), :func:`prepare_trial`,
:func:`write_outputs` (JSON, report, calibrated profile), :func:`load_calibrated_profile`,
:func:`simulate_calibrated` and :func:`simulate_calibrated_recording` (the emulator side of the
calibrated profile).
"""

from exohil.emulators.discrepancy.candidates import VOCABULARY
from exohil.emulators.discrepancy.data import DiscrepancyError, Trial, noise_floor, prepare_trial
from exohil.emulators.discrepancy.profile import (
    CalibratedSuit,
    load_calibrated_profile,
    simulate_calibrated,
    simulate_calibrated_recording,
)
from exohil.emulators.discrepancy.report import write_outputs
from exohil.emulators.discrepancy.workflow import Outcome, run

__all__ = ["VOCABULARY", "CalibratedSuit", "DiscrepancyError", "Outcome", "Trial",
           "load_calibrated_profile", "noise_floor", "prepare_trial", "run",
           "simulate_calibrated", "simulate_calibrated_recording", "write_outputs"]
