"""Appearance the networks never saw, for the recordings: clothing colours,
a ground photograph and a body shape that the still-frame training data provably never draws.

Each part is a switch of :class:`HeldOutConfig` (the ``held_out:`` setting of a recording), all
off by default; off, the recording (its frames, ground truth and cache key) is exactly the clean
one. Every part is outside the training draw by construction, not by chance, so the still
frames already generated keep every byte:

* clothing: HSV saturation >= 0.92, above the 0.81 the still frames' draw can reach
  (:func:`airpose_lib.data.still.appearance.held_out_clothing`);
* ground: a photograph no still frame shows (:func:`held_out_ground_photo`);
* body shape: the person's betas scaled until the largest reaches ``betas_max``, beyond the
  still frames' clip of +-3 (:func:`held_out_betas`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airpose_lib.config_fields import check_fields, require

from ..still.appearance import Appearance, held_out_clothing

__all__ = ["HeldOutConfig", "HELD_OUT_GROUND_PHOTOS", "held_out_ground_photo", "held_out_appearance",
           "held_out_betas"]

#: Salt of the held-out clothing's random stream (the person's own look keeps its stream).
_CLOTHING_SALT = 8191


#: Photographs of ground in scikit-image's wheel that the still frames never use, with the
#: ground size of one of their pixels, metres (:func:`held_out_ground_photo`).
HELD_OUT_GROUND_PHOTOS: dict[str, float] = {"moon": 0.01}


def held_out_ground_photo(name: str = "moon") -> np.ndarray:
    """A ground texture ``(512, 512) uint8`` from a photograph that no still frame shows (its
    own resolution, the brightness stretch of :func:`~airpose_lib.data.still.render.ground_textures`).

    Why: the still frames' ground is one of seven textures, among them every ground-like
    photograph scikit-image ships in its wheel
    (:data:`~airpose_lib.data.still.render.TRAINING_GROUND_PHOTOS`); a real field
    is none of them. ``moon`` (``skimage.data.moon()``, a photograph of the lunar surface,
    public domain) is the one natural-ground photograph of the wheel left: laid at 1 cm a
    pixel (:data:`HELD_OUT_GROUND_PHOTOS`, one tile 5.12 m) its craters become the dips,
    clods and stones, 0.1-0.6 m across, of a bare, trodden field. The drones see 1-2 cm of
    ground per pixel at half resolution (8-12 m away), so the photograph's own detail shows.
    Like the held-out textures of SURREAL's test split (Varol et al. 2017, "Learning from
    synthetic humans", CVPR), the test scene's ground is one the training renders never had.
    """
    if name not in HELD_OUT_GROUND_PHOTOS:
        raise ValueError(f"unknown held-out ground photograph {name!r}; choose from {tuple(HELD_OUT_GROUND_PHOTOS)}")
    from skimage import data as skdata

    from ..still.render import photo_texture  # (lazily: importing render starts VTK)

    return photo_texture(getattr(skdata, name)(), None)


@dataclass(frozen=True)
class HeldOutConfig:
    """Held-out appearance of a recording; every part is off by default.

    With ``enabled=False`` nothing changes and the setting is absent from the recording's cache
    key (:meth:`~airpose_lib.data.sequences.config.SequenceConfig.to_dict`).

    Attributes:
        enabled: apply the parts below at all.
        clothing: shirt and trousers in held-out colours (the person keeps skin, hair and
            garment lengths).
        ground: a held-out ground photograph (a key of :data:`HELD_OUT_GROUND_PHOTOS`, laid at
            its metres per pixel) in place of the grass texture; None = off.
        ground_tint: (3,) RGB tint of the grey photograph (default: dry earth).
        betas_max: scale the person's betas so that the largest magnitude is this (> 3, the
            still frames' clip); None = off. The ground truth has the scaled betas.
    """

    enabled: bool = False
    clothing: bool = False
    ground: str | None = None
    ground_tint: tuple[float, float, float] = (0.62, 0.52, 0.40)
    betas_max: float | None = None

    def __post_init__(self) -> None:
        check_fields(self)
        require(self.ground is None or self.ground in HELD_OUT_GROUND_PHOTOS, "ground",
                f"one of {tuple(HELD_OUT_GROUND_PHOTOS)} or None", self.ground)
        require(len(self.ground_tint) == 3 and all(0 < c <= 1 for c in self.ground_tint), "ground_tint",
                "three values in (0, 1]", self.ground_tint)
        require(self.betas_max is None or self.betas_max > 0, "betas_max", "> 0 or None", self.betas_max)


def held_out_appearance(appearance: Appearance, cfg: HeldOutConfig, appearance_seed: int) -> Appearance:
    """The recording's person's look with the held-out clothing when ``cfg`` asks for it (its own
    random stream, from the person's appearance seed)."""
    if not (cfg.enabled and cfg.clothing):
        return appearance
    return held_out_clothing(appearance, np.random.default_rng([appearance_seed, _CLOTHING_SALT]))


def held_out_betas(betas, cfg: HeldOutConfig) -> np.ndarray:
    """``(10,)`` the person's betas, scaled to ``max |beta| = cfg.betas_max`` when that is on.

    Why scaled, not replaced: the person keeps the direction of their shape (taller, heavier...)
    and only goes further along it, beyond the still frames' draw (``N(0, 1)`` clipped to +-3,
    ``data.still.scene.SceneConfig.beta_clip``): the test bodies of the real data were never drawn
    from the training's shape distribution either (the paper trains on AGORA's scans, tests on
    its own two people).
    """
    betas = np.asarray(betas, dtype=np.float64)
    if not cfg.enabled or cfg.betas_max is None or not np.abs(betas).max() > 0:
        return betas
    return betas * (cfg.betas_max / np.abs(betas).max())
