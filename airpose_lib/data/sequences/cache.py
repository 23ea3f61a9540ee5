"""The disk cache of a profile's recordings: where they live, whether a stored copy is complete
and current, and :func:`ensure_sequences`, which makes only what is missing or outdated."""
from __future__ import annotations

import json
import shutil
from collections.abc import Mapping
from pathlib import Path

from airpose_lib.errors import ConfigError
from airpose_lib.folder_lock import MAKER_WAIT_S, folder_lock
from airpose_lib.paths import cache_dir, profile_name
from airpose_lib.profiles import section_where

from .config import SEQUENCE_GENERATOR_VERSION, SequenceConfig, profile_sequences
from .detections import DETECTOR_VERSION
from .presets import FIELD_PRESETS, profile_field_sequences
from .recording import generate_sequence, refresh_detections

__all__ = ["default_sequence_root", "ensure_sequences"]


def default_sequence_root(profile: str, field: bool = False) -> Path:
    """Where a profile's recordings live by default: ``<kit cache>/data/sequences_<name>``,
    its field recordings (``sequences: field_recordings:``) in ``sequences_<name>_field``
    (``<name>``: :func:`~airpose_lib.paths.profile_name`)."""
    name = profile_name(profile)
    return cache_dir() / "data" / (f"sequences_{name}_field" if field else f"sequences_{name}")


def _detections_current(root: Path) -> bool:
    try:
        return json.loads((root / "sequence.json").read_text()).get("detector_version") == DETECTOR_VERSION
    except (OSError, json.JSONDecodeError):
        return False


def _is_complete(root: Path, config: SequenceConfig) -> bool:
    """The images and ground truth of ``config`` are all there (the detections may be outdated)."""
    meta_path = root / "sequence.json"
    if not meta_path.is_file() or not (root / "ground_truth.npz").is_file():
        return False
    try:
        meta = json.loads(meta_path.read_text())
    except json.JSONDecodeError:
        return False
    same = (meta.get("generator_version") == SEQUENCE_GENERATOR_VERSION
            and json.loads(json.dumps(config.to_dict())) == meta.get("config"))
    if not same:
        return False
    return all(len(list((root / f"machine_{v + 1}" / "images").glob("*.jpg"))) == config.n_frames
               for v in range(config.num_views))


def ensure_sequences(profile: str | None = None, root: str | Path | None = None, *,
                     configs: Mapping[str, SequenceConfig] | None = None, only=None,
                     force: bool = False, progress: bool = False, field: bool = False) -> dict[str, Path]:
    """Generate a profile's recordings unless an identical complete copy exists.

    Args:
        profile: reproduction profile whose ``sequences:`` section lists the recordings.
        root: parent folder (default :func:`default_sequence_root`); recording ``name`` goes to
            ``root/name``.
        configs: recordings to make instead of a profile's.
        only: names to make (default: all).
        force: regenerate even if complete.
        field: the profile's field recordings instead (``sequences: field_recordings:``,
            :func:`~.presets.profile_field_sequences`), by default in their own folder.
    Returns:
        name -> sequence folder (read it with
        :func:`airpose_lib.data.sequences.reader.load_sequence`).
    """
    # A profile gives both the settings and the default folder, as for the still frames
    # (data.still.generate.ensure_still_dataset); explicit settings need an explicit folder.
    if configs is None:
        if profile is None:
            raise ValueError("give a profile or configs")
        configs = profile_field_sequences(profile) if field else profile_sequences(profile)
        if field and not configs:
            raise ConfigError(f"{section_where(profile, 'sequences')} has no field recordings; add "
                              f"`field_recordings: <preset>` (presets: {', '.join(FIELD_PRESETS)})")
    if root is None:
        if profile is None:
            raise ValueError("give root when no profile is given")
        root = default_sequence_root(profile, field)
    root = Path(root)
    names = list(configs) if only is None else list(only)
    unknown = [n for n in names if n not in configs]
    if unknown:
        raise ConfigError(f"unknown recording(s) {unknown}; available: {list(configs)}")
    def current(name: str) -> bool:
        folder = root / name
        return not force and _is_complete(folder, configs[name]) and _detections_current(folder)

    if all(current(name) for name in names):  # readers take no lock
        return {name: root / name for name in names}
    # One writer of the recordings at a time; a second command that needs them (a notebook run
    # beside another) waits for the first instead of rendering into the same .partial folder.
    with folder_lock(root, "recordings folder", stale=(), wait=MAKER_WAIT_S):
        for name in names:
            folder = root / name
            if force or not _is_complete(folder, configs[name]):
                partial = folder.with_name(folder.name + ".partial")
                if partial.exists():
                    shutil.rmtree(partial)  # left by an interrupted run
                try:
                    generate_sequence(configs[name], partial, progress=progress)
                except BaseException:  # a full disk, Ctrl-C: leave no half-made recording behind
                    shutil.rmtree(partial, ignore_errors=True)
                    raise
                if folder.exists():
                    shutil.rmtree(folder)  # outdated
                partial.rename(folder)
            elif not _detections_current(folder):
                refresh_detections(folder, configs[name])  # a new detector model: no re-rendering
    return {name: root / name for name in names}
