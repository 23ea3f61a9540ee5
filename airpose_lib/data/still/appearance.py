"""Appearance of the synthetic people: skin tone, hair and clothing as per-vertex colours.

The body is split into regions by its skinning weights (``model.lbs_weights`` argmax over the 55
SMPL-X joints): torso and collars (shirt), upper arms, forearms, hands, thighs and pelvis
(trousers), shins, feet (shoes), head and neck (skin), with hair taken from the head region by
position. Every sample draws a skin tone, a hair colour, a shirt and trousers colour, sleeve and
trouser lengths and shoes, plus a low-frequency shading pattern, so that a network cannot rely on
one constant look (the paper's AGORA scans are real, clothed people).
"""
from __future__ import annotations

import colorsys
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from airpose_lib.body.joint_sets import SMPLX_JOINT_NAMES

__all__ = [
    "REGIONS",
    "AppearanceConfig",
    "Appearance",
    "body_regions",
    "BodyPaint",
    "sample_appearance",
    "vertex_colors",
    "training_saturation_bound",
    "HELD_OUT_SATURATION",
    "HELD_OUT_VALUE",
    "held_out_clothing_color",
    "held_out_clothing",
]

#: Body regions, in the order of :func:`body_regions`'s ids.
REGIONS: tuple[str, ...] = ("skin", "hair", "torso", "upper_arm", "forearm", "hand",
                            "thigh", "shin", "shoe")
_R = {name: i for i, name in enumerate(REGIONS)}

# Region of the vertices each SMPL-X joint moves most (SMPL-X names the joint at the *start* of
# a bone: the knee joint carries the shin, the shoulder joint the upper arm).
_JOINT_REGION = {
    "pelvis": "thigh", "left_hip": "thigh", "right_hip": "thigh",
    "spine1": "torso", "spine2": "torso", "spine3": "torso",
    "left_collar": "torso", "right_collar": "torso",
    "left_knee": "shin", "right_knee": "shin",
    "left_ankle": "shoe", "right_ankle": "shoe", "left_foot": "shoe", "right_foot": "shoe",
    "neck": "skin", "head": "skin", "jaw": "skin", "left_eye_smplhf": "skin",
    "right_eye_smplhf": "skin",
    "left_shoulder": "upper_arm", "right_shoulder": "upper_arm",
    "left_elbow": "forearm", "right_elbow": "forearm",
    "left_wrist": "hand", "right_wrist": "hand",
}

# Skin tones from light to dark (sRGB, 0..1); a sample interpolates between neighbours.
_SKIN_TONES = np.array([
    [0.98, 0.86, 0.76], [0.93, 0.76, 0.62], [0.85, 0.64, 0.48], [0.72, 0.50, 0.35],
    [0.55, 0.36, 0.24], [0.38, 0.25, 0.17],
])
_HAIR_COLORS = np.array([
    [0.06, 0.05, 0.05], [0.20, 0.13, 0.08], [0.36, 0.24, 0.14], [0.62, 0.48, 0.30],
    [0.85, 0.72, 0.46], [0.55, 0.25, 0.12], [0.62, 0.62, 0.62],
])


@dataclass(frozen=True)
class AppearanceConfig:
    """How much the look varies.

    Attributes:
        long_sleeve_prob: probability of sleeves down to the wrist (else short sleeves).
        long_trouser_prob: probability of trousers down to the shoes (else shorts).
        bald_prob: probability of no hair colour (the head is all skin).
        shading_strength: amplitude of the low-frequency brightness pattern (folds, dirt).
        saturation_max: upper bound of clothing saturation.
    """

    long_sleeve_prob: float = 0.5
    long_trouser_prob: float = 0.75
    bald_prob: float = 0.08
    shading_strength: float = 0.12
    saturation_max: float = 0.85


@dataclass
class Appearance:
    """One person's colours (RGB in [0, 1]) and garment choices.

    Attributes:
        region_colors: ``(len(REGIONS), 3)`` colour per region after the choices below.
        long_sleeves, long_trousers, bald: the garment / hair choices.
        hairline: extra height (m) of the hairline above the default (varies the hair cut).
        shading_phase: ``(4, 4)`` random wave vectors and phases of the shading pattern.
    """

    region_colors: np.ndarray
    long_sleeves: bool
    long_trousers: bool
    bald: bool
    hairline: float
    shading_phase: np.ndarray


def body_regions(lbs_weights: np.ndarray, v_template: np.ndarray, joints_rest: np.ndarray,
                 hairline: float = 0.0) -> np.ndarray:
    """Region id (index into :data:`REGIONS`) of every vertex.

    Args:
        lbs_weights: ``(V, 55)`` skinning weights.
        v_template: ``(V, 3)`` rest-pose vertices (Y up, facing +Z).
        joints_rest: ``(55, 3)`` rest-pose joints.
        hairline: moves the hairline up (positive) or down, metres.
    Returns:
        ``(V,)`` int64.
    """
    owner = np.asarray(lbs_weights).argmax(axis=1)
    lut = np.full(len(SMPLX_JOINT_NAMES), _R["hand"], dtype=np.int64)  # finger joints -> hand
    for name, region in _JOINT_REGION.items():
        lut[SMPLX_JOINT_NAMES.index(name)] = _R[region]
    region = lut[owner]
    head = SMPLX_JOINT_NAMES.index("head")
    region[_hair_mask(owner == head, np.asarray(v_template) - joints_rest[head], hairline)] = _R["hair"]
    return region


def _hair_mask(on_head: np.ndarray, rel: np.ndarray, hairline: float) -> np.ndarray:
    """Head vertices above the forehead or on the back of the skull; ``rel (V, 3)`` from the head joint."""
    top = rel[:, 1] > 0.085 + hairline
    back = (rel[:, 2] < 0.01) & (rel[:, 1] > hairline)
    return on_head & (top | back)


class BodyPaint:
    """Precomputed regions of one body model; turns an :class:`Appearance` into vertex colours.

    Args:
        lbs_weights: ``(V, 55)``; v_template: ``(V, 3)``; joints_rest: ``(55, 3)`` (rest pose).
    """

    def __init__(self, lbs_weights: np.ndarray, v_template: np.ndarray, joints_rest: np.ndarray) -> None:
        owner = np.asarray(lbs_weights).argmax(axis=1)
        head = SMPLX_JOINT_NAMES.index("head")
        self.v_template = np.asarray(v_template, dtype=np.float64)
        self.regions = body_regions(lbs_weights, v_template, joints_rest)
        self._on_head = owner == head
        self._head_rel = self.v_template - joints_rest[head]

    @classmethod
    def from_model(cls, model) -> "BodyPaint":
        """From an ``smplx.SMPLX`` model (uses its skinning weights, template and joint regressor)."""
        v = model.v_template.detach().cpu().double()
        J = model.J_regressor.detach().cpu().double() @ v
        return cls(model.lbs_weights.detach().cpu().numpy(), v.numpy(), J.numpy())

    def regions_for(self, appearance: "Appearance") -> np.ndarray:
        """``(V,)`` region ids with this person's hairline."""
        if appearance.hairline == 0.0:
            return self.regions
        region = self.regions.copy()
        head = self._on_head
        region[head] = _R["skin"]
        region[_hair_mask(head, self._head_rel, appearance.hairline)] = _R["hair"]
        return region

    def colors(self, appearance: "Appearance", shading_strength: float = 0.12) -> np.ndarray:
        """``(V, 3)`` uint8 vertex colours (see :func:`vertex_colors`)."""
        return vertex_colors(appearance, self.regions_for(appearance), self.v_template, shading_strength)


def _clothing_color(rng: np.random.Generator, saturation_max: float) -> np.ndarray:
    h = rng.uniform()
    s = rng.uniform(0.0, saturation_max) ** 1.3  # many muted colours, some vivid
    v = rng.uniform(0.12, 0.95)
    return np.array(colorsys.hsv_to_rgb(h, s, v))


def _garment_regions(long_sleeves: bool, long_trousers: bool) -> tuple[list[int], list[int]]:
    """Region ids the shirt and the trousers cover, given the garment lengths."""
    shirt = [_R["torso"], _R["upper_arm"]] + ([_R["forearm"]] if long_sleeves else [])
    trousers = [_R["thigh"]] + ([_R["shin"]] if long_trousers else [])
    return shirt, trousers


def training_saturation_bound(cfg: AppearanceConfig = AppearanceConfig()) -> float:
    """Supremum of the HSV saturation ``(max - min) / max`` of every colour
    :func:`sample_appearance` gives a person, for the settings ``cfg``.

    Clothing: ``s = U(0, saturation_max) ** 1.3`` (shoes: ``U(0, 0.4) ** 1.3``) and
    ``colorsys.hsv_to_rgb`` keeps ``s`` as the colour's saturation; skin tones reach 0.55 and
    hair colours 0.79 (their gains scale all channels alike, a clip at 1 only lowers it).
    """
    skin_hair = np.concatenate([_SKIN_TONES, _HAIR_COLORS])
    sat = (skin_hair.max(1) - skin_hair.min(1)) / skin_hair.max(1)
    return float(max(cfg.saturation_max ** 1.3, 0.4 ** 1.3, sat.max()))


#: HSV saturation range of the held-out clothing colours (:func:`held_out_clothing`).
HELD_OUT_SATURATION: tuple[float, float] = (0.92, 1.0)
#: HSV value range of the held-out clothing colours (dark colours lose their hue).
HELD_OUT_VALUE: tuple[float, float] = (0.35, 1.0)


def held_out_clothing_color(rng: np.random.Generator) -> np.ndarray:
    """``(3,)`` RGB of a clothing colour from the part of colour space the still frames never
    draw: HSV saturation in :data:`HELD_OUT_SATURATION`, above :func:`training_saturation_bound`
    (0.81 with the kit's settings), any hue, value in :data:`HELD_OUT_VALUE`: vivid, fully
    saturated garments (high-visibility vests, sports kit).

    Why: networks trained on synthetic people meet clothing at test time that their training
    renders never showed; the paper trains on AGORA's scanned people and tests on its own
    footage. Holding out part of the appearance space at test time measures that shift, as
    SURREAL's split does (Varol et al. 2017, "Learning from synthetic humans", CVPR: its test
    people wear clothing textures that no training person wears). Here the held-out part is
    one the still-frame draw provably never reaches, so the still data keep every byte.
    """
    h = rng.uniform()
    s = rng.uniform(*HELD_OUT_SATURATION)
    v = rng.uniform(*HELD_OUT_VALUE)
    return np.array(colorsys.hsv_to_rgb(h, s, v))


def held_out_clothing(appearance: Appearance, rng: np.random.Generator) -> Appearance:
    """The same person (skin, hair, garment lengths, shading) in a shirt and trousers of
    held-out colours (:func:`held_out_clothing_color`); the shoes keep theirs."""
    colors = appearance.region_colors.copy()
    shirt, trousers = _garment_regions(appearance.long_sleeves, appearance.long_trousers)
    colors[shirt] = held_out_clothing_color(rng)
    colors[trousers] = held_out_clothing_color(rng)
    return dataclasses.replace(appearance, region_colors=colors)


def sample_appearance(rng: np.random.Generator, cfg: AppearanceConfig = AppearanceConfig()) -> Appearance:
    """Draw a skin tone, hair colour, clothing colours and garment lengths."""
    t = rng.uniform(0.0, len(_SKIN_TONES) - 1)
    i = min(int(t), len(_SKIN_TONES) - 2)
    skin = (1 - (t - i)) * _SKIN_TONES[i] + (t - i) * _SKIN_TONES[i + 1]
    skin = np.clip(skin * rng.uniform(0.92, 1.05), 0.0, 1.0)
    hair = np.clip(_HAIR_COLORS[int(rng.integers(len(_HAIR_COLORS)))] * rng.uniform(0.8, 1.2), 0, 1)
    shirt = _clothing_color(rng, cfg.saturation_max)
    trousers = _clothing_color(rng, cfg.saturation_max)
    shoes = _clothing_color(rng, 0.4) * 0.6
    long_sleeves = bool(rng.uniform() < cfg.long_sleeve_prob)
    long_trousers = bool(rng.uniform() < cfg.long_trouser_prob)
    bald = bool(rng.uniform() < cfg.bald_prob)
    hairline = float(rng.uniform(-0.02, 0.03))
    colors = np.empty((len(REGIONS), 3))
    colors[:] = skin  # skin, hands, and forearms / shins the garments leave bare
    colors[_R["hair"]] = skin if bald else hair
    shirt_regions, trouser_regions = _garment_regions(long_sleeves, long_trousers)
    colors[shirt_regions] = shirt
    colors[trouser_regions] = trousers
    colors[_R["shoe"]] = shoes
    phase = np.concatenate([rng.normal(0.0, 6.0, size=(4, 3)), rng.uniform(0, 2 * math.pi, size=(4, 1))], 1)
    return Appearance(colors, long_sleeves, long_trousers, bald, hairline, phase)


def vertex_colors(appearance: Appearance, regions: np.ndarray, v_template: np.ndarray,
                  shading_strength: float = 0.12) -> np.ndarray:
    """Per-vertex colours ``(V, 3)`` uint8 of a person.

    Args:
        appearance: the sampled look.
        regions: ``(V,)`` region ids (:func:`body_regions`).
        v_template: ``(V, 3)`` rest-pose vertices; the shading pattern is a sum of sines over the
            rest pose, so it moves with the body like cloth folds would.
        shading_strength: amplitude of the brightness pattern.
    """
    base = appearance.region_colors[regions]
    waves = appearance.shading_phase
    pattern = np.sin(np.asarray(v_template) @ waves[:, :3].T + waves[:, 3]).mean(axis=1)  # (V,)
    shade = 1.0 + shading_strength * pattern
    return np.clip(base * shade[:, None] * 255.0 + 0.5, 0, 255).astype(np.uint8)
