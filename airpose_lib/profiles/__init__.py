"""The reproduction profiles: ``smoke``, ``cpu`` and ``paper`` (one YAML file each, in this folder).

A profile is the one place where sizes live: every section configures one part of the kit
(``data: still:`` the still-frame data, ``sequences:`` the recordings, ``train:``, ``pretrain:``,
``prior:``, ``finetune:``, ``fitting:``, ``notebooks:`` the notebooks' parameters). This module is
the only code that knows where the files are and how they are read; each package turns its own
section into its config (``train.load_train_config``, ``data.generate.profile_config`` ...).

A profile is named (``"smoke"``) or given as the path of a YAML file of the same format. Readers
raise :class:`~airpose_lib.errors.ProfileError` (one line naming the file and the fix; the
``airpose`` command exits with status 2). Files are read on every call: they are small, and a
test or a user may edit one between calls. Imports nothing of the kit but ``errors``, so that
every layer may use it.
"""
from __future__ import annotations

from pathlib import Path

import yaml

from airpose_lib.errors import ProfileError

__all__ = ["PROFILES_DIR", "ProfileError", "profile_names", "profile_path", "read_profile", "profile_section"]

#: Folder of the kit's ``<name>.yaml`` profile files.
PROFILES_DIR = Path(__file__).resolve().parent


def profile_names(folder: str | Path = PROFILES_DIR) -> list[str]:
    """Names of the profiles in ``folder`` (the kit's: ``["cpu", "paper", "smoke"]``), sorted."""
    return sorted(p.stem for p in Path(folder).glob("*.yaml"))


def profile_path(profile: str | Path, folder: str | Path = PROFILES_DIR) -> Path:
    """The file of a profile: ``<folder>/<name>.yaml`` for a name, else the YAML path itself.

    Raises:
        ProfileError: no such profile or file.
    """
    path = Path(profile)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise ProfileError(f"profile file {path} does not exist; give an existing YAML file or one of the "
                               f"kit's profiles ({', '.join(profile_names())})")
        return path
    path = Path(folder) / f"{profile}.yaml"
    if not path.is_file():
        raise ProfileError(f"unknown profile {str(profile)!r} (no {path}); available: "
                           f"{', '.join(profile_names(folder))}, or give the path of a profile YAML file")
    return path


def read_profile(profile: str | Path, folder: str | Path = PROFILES_DIR) -> dict:
    """A profile file's content: ``{section: settings}``.

    Raises:
        ProfileError: no such profile, an empty file, invalid YAML, or not a mapping of sections.
    """
    path = profile_path(profile, folder)
    try:
        raw = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        raise ProfileError(f"{path} is not valid YAML ({type(e).__name__}: {' '.join(str(e).split())}); "
                           "fix the file") from None
    if raw is None:
        raise ProfileError(f"{path} is empty; a profile is a YAML mapping of sections (train:, data: ...), "
                           f"see the kit's profiles in {PROFILES_DIR}")
    if not isinstance(raw, dict):
        raise ProfileError(f"{path} must be a YAML mapping of sections (train:, data: ...), "
                           f"not a {type(raw).__name__}; fix the file")
    return raw


def profile_section(profile: str | Path, section: str, *, required: str | None = None,
                    folder: str | Path = PROFILES_DIR) -> dict:
    """One section of a profile, as a new dict.

    A section written empty (``finetune:`` or ``finetune: {}``) gives ``{}``: the defaults, as the
    file says. A section that is not in the file at all is a mistake (a user's profile that lacks
    what the command reads would otherwise run silently on the defaults) and raises.

    Args:
        profile: a profile name or the path of a profile YAML file.
        section: the section's key; dots go deeper (``"data.still"`` is ``data: still:``).
        required: what the section holds (``"the still-frame dataset sizes"``): an empty section
            then raises too, naming the file, the section and what it is for.
        folder: where named profiles live.
    Raises:
        ProfileError: no such profile, a missing section (or an empty required one), or a section
            that is not a mapping.
    """
    path = profile_path(profile, folder)
    value = read_profile(path)
    label = ": ".join(section.split(".")) + ":"
    for key in section.split("."):
        if not isinstance(value, dict) or key not in value:
            what = f" ({required})" if required is not None else ""
            raise ProfileError(f"{path} has no `{label}` section{what}; add one (the kit's profiles in "
                               f"{PROFILES_DIR} have it; an empty `{label}` takes the defaults)")
        value = value[key]
    if not value:
        if required is not None:
            raise ProfileError(f"{path} has an empty `{label}` section ({required}); fill it in "
                               f"(the kit's profiles in {PROFILES_DIR} have it)")
        return {}
    if not isinstance(value, dict):
        raise ProfileError(f"{path}: `{label}` must be a mapping of settings, not a {type(value).__name__}; "
                           "fix the file")
    return dict(value)
