"""Settings of the synthetic still-frame dataset: :class:`GenerationConfig` (everything a dataset
depends on, with its fingerprint), made from a profile's ``data: still:`` section by the entry
(:meth:`GenerationConfig.from_dict`); the default folder is ``RunFolders.still``."""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass, field

from airpose_lib.config_fields import check_fields, check_keys, ranged
from airpose_lib.errors import ConfigError

from .appearance import AppearanceConfig
from .scene import SceneConfig

__all__ = ["GENERATOR_VERSION", "SPLITS", "GenerationConfig"]

#: Bumped whenever the same configuration would produce different shards.
#: 2: test crops are jittered like training crops; test shards also hold the tight-box crops.
#: 3: a validation split (``val_fraction``) between the training and the test shards.
GENERATOR_VERSION = 3

#: The splits of a generated dataset, in shard order. ``val`` is made like ``test`` (test-protocol
#: crops, tight crops too, subjects of its own): every choice is made on it, and ``test`` is read
#: only to make the reported tables.
SPLITS = ("train", "val", "test")

# -- configuration --------------------------------------------------------------------------------
@dataclass(frozen=True)
class GenerationConfig:
    """Everything that determines a still-frame dataset.

    Attributes:
        num_samples: accepted multi-view samples (pairs for two views).
        shard_size: samples per shard file (the unit of resumption and verification).
        seed: master seed.
        crop_size: side S of the rendered crops (the network input; 224 in the paper).
        test_fraction: share of shards (the last ones, hence distinct subjects) in the test split;
            at least one test shard.
        val_fraction: share of shards in the validation split, the shards just before the test
            split (their own seeds and subjects, drawn like the test split); at least one
            validation shard when positive and the dataset has three shards or more.
        image_format: ``"jpg"`` or ``"png"`` (lossless, ~3x larger).
        jpeg_quality: JPEG quality 1-100.
        anti_aliasing: MSAA on the rendered crops (slow in software rendering).
        blur_sigma: Gaussian blur (pixels) of the rendered crop before padding: softens
            aliased edges and textures like a real lens and downscaling do (0 = none).
        test_crops: how the test split's crops are drawn. ``"jittered"`` (default, the official
            code: ``copenet/dsets/aerialpeople.py`` enlarges every box, test split included, by a
            random 0-200 px, so test crops come from the training distribution; deterministic per
            sample, since each sample has its own generator) or ``"tight"`` (the box + 20 px of
            the paper's text, outside the training range of the crop scale s).
        tight_test_crops: test shards also store the tight-box crops (``images_tight``,
            ``P_tight``) so that both protocols are evaluated on the same samples.
        body_source: ``"open"`` or ``"smplx"`` (:func:`airpose_lib.body.load_body_model`).
        max_attempts_per_sample: a shard gives up (error) after this many attempts per sample.
        scene: person / camera / crop / environment sampling.
        appearance: skin, hair and clothing sampling.
    """

    num_samples: int = ranged(300, ge=1)
    shard_size: int = ranged(50, ge=1)
    seed: int = 0
    crop_size: int = ranged(224, ge=8)
    test_fraction: float = ranged(0.1, ge=0, lt=1)
    val_fraction: float = ranged(0.1, ge=0, lt=1)
    image_format: str = "jpg"
    jpeg_quality: int = ranged(95, ge=1, le=100)
    anti_aliasing: bool = False
    blur_sigma: float = ranged(0.5, ge=0)
    test_crops: str = "jittered"
    tight_test_crops: bool = True
    body_source: str = "open"
    max_attempts_per_sample: int = ranged(20, ge=1)
    scene: SceneConfig = field(default_factory=SceneConfig)
    appearance: AppearanceConfig = field(default_factory=AppearanceConfig)

    def __post_init__(self) -> None:
        check_fields(self, convert=False)  # types and declared ranges (ints stay ints: the fingerprint)
        if self.test_crops not in ("jittered", "tight"):
            raise ConfigError(f"test_crops must be 'jittered' or 'tight', got {self.test_crops!r}")
        if self.image_format not in ("jpg", "png"):
            raise ConfigError(f"image_format must be 'jpg' or 'png', got {self.image_format!r}")
        if self.val_fraction + self.test_fraction >= 1.0:
            raise ConfigError(f"val_fraction + test_fraction must be < 1, got {self.val_fraction} + "
                              f"{self.test_fraction}")

    # -- shards -----------------------------------------------------------------------------------
    @property
    def num_shards(self) -> int:
        return math.ceil(self.num_samples / self.shard_size)

    @property
    def num_test_shards(self) -> int:
        if self.num_shards < 2:
            return 0  # a one-shard dataset is all training data
        return min(self.num_shards - 1, max(1, round(self.test_fraction * self.num_shards)))

    @property
    def num_val_shards(self) -> int:
        if self.val_fraction == 0.0 or self.num_shards < 3:
            return 0  # a dataset of one or two shards has no room for a third split
        room = self.num_shards - self.num_test_shards - 1  # at least one training shard stays
        return min(room, max(1, round(self.val_fraction * self.num_shards)))

    def shard_samples(self, k: int) -> int:
        """Samples in shard ``k`` (the last one may be smaller)."""
        return min(self.shard_size, self.num_samples - k * self.shard_size)

    def shard_split(self, k: int) -> str:
        """``"train"``, ``"val"`` or ``"test"`` (:data:`SPLITS`): the last shards (new subjects)
        are the test split, the ones before them the validation split."""
        if k >= self.num_shards - self.num_test_shards:
            return "test"
        if k >= self.num_shards - self.num_test_shards - self.num_val_shards:
            return "val"
        return "train"

    # -- (de)serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain dict (lists for tuples) for YAML/JSON."""
        return _plain(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, d: dict) -> GenerationConfig:
        """Inverse of :meth:`to_dict`; missing keys take the defaults, unknown keys raise."""
        d = dict(d or {})
        scene = _build(SceneConfig, d.pop("scene", None) or {}, "scene")
        appearance = _build(AppearanceConfig, d.pop("appearance", None) or {}, "appearance")
        return _build(cls, d, "data", scene=scene, appearance=appearance)

    def replace(self, **changes) -> GenerationConfig:
        return dataclasses.replace(self, **changes)

    def fingerprint(self) -> str:
        """SHA-256 of the configuration and generator version (what a dataset must match)."""
        blob = json.dumps({"generator_version": GENERATOR_VERSION, "config": self.to_dict()},
                          sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def _build(cls, d: dict, where: str, **extra):
    check_keys(d, cls, where)
    return cls(**{k: _tuplify(v) for k, v in d.items()}, **extra)


def _tuplify(x):
    """YAML lists -> tuples (every sequence setting is a tuple), recursively."""
    return tuple(_tuplify(v) for v in x) if isinstance(x, list) else x
