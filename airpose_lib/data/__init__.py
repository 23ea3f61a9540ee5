"""The kit's data, in three wings by job:

* ``still/``: the synthetic two-drone still frames (scene and pose samplers, appearance,
  off-screen rendering, checksummed shards and manifests, ``StillFrameDataset``, the mirror
  augmentation; ``airpose data generate``).
* ``sequences/``: recordings, kit or real: the simulated ones (motions, drones, detectors,
  markers, frames; ``airpose data sequence``) and the one folder layout every recording is
  written in and read from (``sequences.layout``, ``sequences.writer``, ``sequences.reader``:
  ``load_sequence``; the detector files' formats in ``sequences.detector_files``).
* ``official/``: the authors' releases (``official.synthetic``, ``official.real``).

``network_input`` (person box, previous-box rule, crop, normalisation) is shared by the still
frames, the drones and fine-tuning, and sits beside the wings.

The names below are the entry points, each written once with its module, and imported on first
use, so ``import airpose_lib.data`` stays cheap and pulls in neither VTK nor torch. Anything else
is imported from its module (``from airpose_lib.data.still.scene import look_at_extrinsics``).
"""
from __future__ import annotations

from airpose_lib._lazy import lazy_namespace

_EXPORTS = {
    # still frames
    **dict.fromkeys(("SceneConfig", "sample_person", "sample_cameras", "sample_environment"), "still.scene"),
    "sample_body_pose": "still.poses",
    **dict.fromkeys(("AppearanceConfig", "sample_appearance", "BodyPaint"), "still.appearance"),
    **dict.fromkeys(("SceneRenderer", "ground_textures"), "still.render"),  # imports VTK
    **dict.fromkeys(("DatasetError", "ShardIntegrityError", "load_manifest"), "still.manifest"),
    **dict.fromkeys(("GENERATOR_VERSION", "GenerationConfig"), "still.config"),
    "StillFrameGenerator": "still.frames",
    **dict.fromkeys(("generate_still_dataset", "ensure_still_dataset"), "still.generate"),
    **dict.fromkeys(("StillFrameDataset", "split_arrays", "denormalize_images"), "still.dataset"),
    # recordings
    "SequenceConfig": "sequences.config",
    "ensure_sequences": "sequences.cache",
    "SequenceFormatError": "sequences.layout",
    "OfficialLayoutWriter": "sequences.writer",
    **dict.fromkeys(("Sequence", "load_sequence"), "sequences.reader"),
    # the authors' releases
    "OfficialSyntheticDataset": "official.synthetic",
    "load_official_real": "official.real",
    # the network's input (person box, previous-box rule, crop, normalisation)
    **dict.fromkeys(("IMAGENET_MEAN", "IMAGENET_STD", "person_box", "hold_boxes", "crop_input", "network_camera",
                     "network_box_margin"), "network_input"),
}

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_namespace(__name__, globals(), (), _EXPORTS)
