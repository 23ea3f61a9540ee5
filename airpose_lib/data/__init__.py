"""Synthetic data of the kit: scene and pose samplers, appearance, off-screen rendering, shards,
manifests and the PyTorch datasets.

Modules: ``scene`` (people, drone cameras, crop boxes, environment), ``poses`` (plausible body
poses), ``motions`` and ``sequences`` (simulated recordings), ``detections`` (simulated keypoint
detectors), ``official_layout`` (the official real-data folder layout, ``load_sequence``), ``markers``
(ArUco markers on the ground: detection, camera poses, UAV 2 in UAV 1),
``appearance`` (skin / hair / clothing colours), ``render`` (textured scenes, pyvista),
``shards`` and ``manifest`` (files on disk), ``still_config`` (still-frame dataset settings),
``still_frames`` (sampling and rendering one shard's still frames), ``generate`` (shards on disk,
resumption, workers: ``airpose data generate``), ``dataset`` (``StillFrameDataset``), ``mirror``
(the left-right mirror augmentation),
``network_input`` (how a frame becomes the network's input: person box, previous-box rule,
crop, normalisation; shared by the drones and fine-tuning).

Names are imported lazily, so ``import airpose_lib.data`` stays cheap and pulls in neither VTK
nor torch until they are used.
"""
from __future__ import annotations

from airpose_lib._lazy import lazy_namespace

_EXPORTS = {
    # scene
    "SceneConfig": "still.scene", "sample_person": "still.scene", "sample_cameras": "still.scene",
    "sample_environment": "still.scene",
    # poses
    "sample_body_pose": "still.poses",
    # appearance
    "AppearanceConfig": "still.appearance", "sample_appearance": "still.appearance", "BodyPaint": "still.appearance",
    # rendering
    "SceneRenderer": "still.render", "ground_textures": "still.render",
    # files
    "DatasetError": "still.manifest", "ShardIntegrityError": "still.manifest", "load_manifest": "still.manifest",
    # generation
    "GENERATOR_VERSION": "still.config", "GenerationConfig": "still.config",
    "profile_config": "still.config", "default_root": "still.config",
    "StillFrameGenerator": "still.frames", "generate_still_dataset": "still.generate",
    "ensure_still_dataset": "still.generate",
    # datasets
    "StillFrameDataset": "still.dataset", "denormalize_images": "still.dataset",
    # the network's input (person box, previous-box rule, crop, normalisation)
    "IMAGENET_MEAN": "network_input", "IMAGENET_STD": "network_input",
    "person_box": "network_input", "hold_boxes": "network_input", "crop_input": "network_input",
    "network_camera": "network_input", "network_box_margin": "network_input",
}

# Other modules' public names (their ``__all__``) are found on first use, in this order; the
# renderer comes last because importing it starts VTK.
_SEARCHED = ("official.synthetic", "official.real", "sequences.layout", "sequences", "sequences.markers",
             "sequences.motions", "sequences.detections", "still.poses", "still.scene", "still.appearance", "still.manifest", "still.shards", "still.config",
             "still.frames", "still.generate",
             "still.mirror", "still.dataset", "still.render")

__all__ = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_namespace(__name__, globals(), _SEARCHED, _EXPORTS, skip_failing=True)
