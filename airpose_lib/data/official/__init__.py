"""Loaders of the authors' releases: ``synthetic`` (the copenet_synthetic still frames, items as
:class:`~airpose_lib.data.still.dataset.StillFrameDataset`'s) and ``real`` (the copenet_dji
recordings: splits, marker poses, read through the one recording reader
:func:`airpose_lib.data.sequences.reader.load_sequence`).

Nothing is imported here: import from the module (``airpose_lib.data.official.real``).
"""
