"""The kit's still frames: two-view training samples drawn, rendered, stored in checksummed
shards and read back as a PyTorch dataset (``airpose data generate``).

Modules: ``scene`` (people, drone cameras, crop boxes, environment), ``poses`` (plausible body
poses), ``appearance`` (skin / hair / clothing colours), ``render`` (textured scenes, pyvista),
``config`` (the dataset's settings, a profile's ``data: still:``), ``frames`` (sampling and
rendering one shard's frames), ``shards`` and ``manifest`` (the files on disk and their
checksums), ``generate`` (shards on disk, resumption, workers), ``dataset``
(``StillFrameDataset``), ``mirror`` (the left-right mirror augmentation), ``training_input``
(the crop size and camera of the data a training config names).

Nothing is imported here: import from the module (``airpose_lib.data.still.generate``), so that
importing one module pulls in neither VTK nor torch unless it needs them.
"""
