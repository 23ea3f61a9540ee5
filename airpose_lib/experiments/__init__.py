"""End-to-end experiments that several notebooks share (each step cached on disk).

- :mod:`.recordings`: the paper's real-data section on two-drone recordings: networks of Table I,
  fine-tuning on person 1, estimates on both persons, AirPose+, and the error tables against the
  ground truth of the kit's generated recordings (notebooks 03, 04, 05), its stages in
  :mod:`.recording_inputs`, :mod:`.recording_finetune`, :mod:`.recording_diagnostic`,
  :mod:`.recording_estimates` and :mod:`.recording_cache`; :mod:`.recording_tables`: the tables and
  figure inputs those notebooks show of it.
- :mod:`.ablation`: Table I, the variants trained (or the official checkpoints) and evaluated,
  the mean-body references, the claims, the results bundle (notebook 02); :mod:`.ablation_samples`: its
  qualitative samples.
- :mod:`.online`: drone fleets over a recording, online = offline, faults, float16 (notebook 06).
- :mod:`.body_model`: the shape-space sweep of notebook 00.
- :mod:`.scene`: the 3D scene of a recording (notebook 07).

Notebooks import these modules by name; the package imports only ``.recordings``.
"""
from .recordings import RecordingExperiment, run_recording_experiment

__all__ = ["RecordingExperiment", "run_recording_experiment"]
