"""The disk cache of a profile's recordings: where they live, whether a stored copy is complete
and current, and :func:`ensure_sequences`, which makes only what is missing or outdated."""
from __future__ import annotations

import json
import shutil
from collections.abc import Mapping
from pathlib import Path

from airpose_lib.errors import ConfigError
from airpose_lib.folder_lock import MAKER_WAIT_S, folder_lock

from .config import SEQUENCE_GENERATOR_VERSION, SequenceConfig
from .detections import DETECTOR_VERSION
from .recording import generate_sequence, refresh_detections

__all__ = ["ensure_sequences"]


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


def ensure_sequences(configs: Mapping[str, SequenceConfig], root: str | Path, *, only=None,
                     force: bool = False, progress: bool = False) -> dict[str, Path]:
    """Generate recordings unless an identical complete copy exists.

    Args:
        configs: name -> the recording's settings (a profile's: ``configs.sequences``, or its
            field recordings ``configs.field_sequences``,
            :class:`~airpose_lib.experiments.configs.KitConfigs`).
        root: parent folder (a profile's: ``configs.folders.sequences(field)``); recording
            ``name`` goes to ``root/name``.
        only: names to make (default: all).
        force: regenerate even if complete.
    Returns:
        name -> sequence folder (read it with
        :func:`airpose_lib.data.sequences.reader.load_sequence`).
    """
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
