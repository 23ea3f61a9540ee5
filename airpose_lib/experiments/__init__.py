"""End-to-end experiments that several notebooks share (each step cached on disk).

- :mod:`.recordings`: the paper's real-data section on two-drone recordings: networks of Table I,
  fine-tuning on person 1, estimates on both persons, AirPose+, and the error tables against the
  ground truth of the kit's generated recordings (notebooks 03, 04, 05).
"""
from .recordings import RecordingExperiment, default_experiment_dir, run_recording_experiment

__all__ = ["RecordingExperiment", "default_experiment_dir", "run_recording_experiment"]
