"""Named field presets of the recordings: a camera pipeline
(:class:`~.field.FieldConfig`) and held-out appearance (:class:`~.held_out.HeldOutConfig`)
together, so that a profile turns "recordings that behave like field footage" on with one name
(``sequences: field_recordings: dji``, :func:`field_variant`).
"""
from __future__ import annotations

import dataclasses

from airpose_lib.errors import ConfigError, ProfileSettingError

from .config import SequenceConfig, sequence_configs_from_profile
from .field import RENDER_GAMMA, FieldConfig
from .held_out import HeldOutConfig
from .markers import marker_layout

__all__ = ["FIELD_PRESETS", "field_variant", "field_sequence_configs_from_profile"]

FIELD_PRESETS: dict[str, tuple[FieldConfig, HeldOutConfig]] = {
    # The paper's DJI drones filming a person in daylight (the values and their sources are in
    # the docstrings of data.sequences.field): half a stop under (a bright sky in the frame of
    # the circling drone), a warm cast of a low sun; the normal colour profile's tone curve
    # (Rec. 709, close to the renders' 2.2, so unchanged); mild low-ISO sensor noise; a 180-degree
    # shutter (1/60 s at 30 fps); the Mavic lens's barrel distortion (k1 -0.1, k2 0.05, inside
    # the calibrations' range); video compression as a JPEG pass at quality 50. The intrinsics
    # are the paper's calibrated DJI cameras (config.PAPER_CAMERAS, every recording's default).
    # Appearance: held-out clothing colours and the held-out ground photograph; body shapes
    # stay the persons' own (a shape beyond the training draw is specific to each person, so
    # fine-tuning on person 1 could not be expected to close it on person 2: it is left to
    # `held_out: betas_max` as a separate measurement).
    "dji": (
        FieldConfig(enabled=True, exposure_ev=-0.5, white_balance=(1.08, 1.0, 0.88), gamma=RENDER_GAMMA,
                    shot_noise=0.002, read_noise=0.004, shutter=0.5, distortion=(-0.1, 0.05), jpeg_quality=50),
        HeldOutConfig(enabled=True, clothing=True, ground="moon"),
    ),
}
"""Preset name -> (camera pipeline, held-out appearance)."""


def field_variant(config: SequenceConfig, preset: str) -> SequenceConfig:
    """``config`` (the same person, motion, flights and seeds) with the preset's camera pipeline
    and held-out appearance: the clean recording's field twin."""
    if preset not in FIELD_PRESETS:
        raise ConfigError(f"unknown field preset {preset!r}; choose from {tuple(FIELD_PRESETS)}")
    field, held_out = FIELD_PRESETS[preset]
    return dataclasses.replace(config, field=field, held_out=held_out)


def field_sequence_configs_from_profile(section, where: str = "a `sequences:` profile section") -> dict[str, SequenceConfig]:
    """The field twins of a ``sequences:`` section's recordings: each recording through the
    preset named by ``field_recordings:`` (same names); ``{}`` when the section has none.

    ``field_markers:`` (a :class:`~.markers.MarkerLayout`'s settings, ``{}`` for the default)
    puts ArUco markers on the twins' ground only. Markers in the frames are a scene the networks
    never trained on: on the clean recordings they would stop being the control that shows the
    field gap (on person 2 of cpu they raised the pre-trained AirPose MPJPE from 0.068 to 0.178 m).
    """
    section = dict(section)
    preset, markers = section.get("field_recordings"), section.get("field_markers")
    if preset is None:
        if markers is not None:
            raise ProfileSettingError(f"{where}: field_markers: needs `field_recordings: <preset>` "
                                      f"(presets: {', '.join(FIELD_PRESETS)})")
        return {}
    if preset not in FIELD_PRESETS:
        raise ProfileSettingError(f"{where}: field_recordings: unknown preset {preset!r}; "
                                  f"choose from {tuple(FIELD_PRESETS)}")
    layout = marker_layout(markers, f"{where}: field_markers:", ProfileSettingError)
    twins = {name: field_variant(c, preset) for name, c in sequence_configs_from_profile(section, where).items()}
    return twins if layout is None else {name: dataclasses.replace(c, markers=layout) for name, c in twins.items()}
