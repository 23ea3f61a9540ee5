"""The reproduction profiles: ``smoke``, ``cpu`` and ``paper`` (one YAML file each, in this folder),
and ``cpu_paper_layout`` (cpu on still frames with the paper's camera layout).

A profile is the one place where sizes live: every section configures one part of the kit
(``data: still:`` the still-frame data, ``sequences:`` the recordings, ``train:``, ``pretrain:``,
``prior:``, ``finetune:``, ``fitting:``, ``notebooks:`` the notebooks' parameters). This module is
the only code that knows where the files are and how they are read. The entry turns every section
into its package's config once, through :func:`section_config` (unknown keys with the closest known
one, bad values, both named with the file and the section):
:func:`airpose_lib.reproduce.configs.kit_configs`, called by the ``airpose`` commands,
``airpose reproduce`` and a notebook's set-up; the packages below take those configs and read no
profile.

A profile may start from another: ``inherits: cpu`` (a profile name: ``cpu.yaml`` beside the file,
else the kit's; or a YAML path relative to the file) takes that profile's sections and lays its
own over them, mapping by mapping (a value that is not a mapping, a list or an empty section
included, replaces the inherited one), so that a variant of a profile (``cpu_paper_layout``: cpu
on other data) says only what differs.

A profile is named (``"smoke"``) or given as the path of a YAML file of the same format. Readers
raise :class:`~airpose_lib.errors.ProfileError` (one line naming the file and the fix; the
``airpose`` command exits with status 2).

A run reads its profile once: :func:`loaded` reads the file (and those it inherits from) and gives
a :class:`Profile`, which *is* the name or path it was given as (a ``str``: run folders, records
and messages stay as they were) and carries the sections read. Every reader here takes it in place
of a name and uses those sections, so that a command, a notebook or a reproduction types one
reading and a file edited while it runs cannot change its later steps (``airpose`` loads
``--profile`` once; ``reproduce`` also refuses to go on when the file changed under a run). A
plain name or path is read afresh on every call. Imports nothing of the kit but the helpers
``errors`` and ``config_fields``, so that every layer may use it.
"""
from __future__ import annotations

import copy
import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from airpose_lib import config_fields
from airpose_lib.config_fields import config_from
from airpose_lib.errors import ProfileError, ProfileSettingError

__all__ = ["PROFILES_DIR", "INHERITS", "SECTIONS", "DATA_SECTIONS", "ProfileError", "ProfileSettingError", "Profile", "loaded", "profile_names",
           "profile_path", "read_profile", "profile_section", "section_where", "section_config"]

#: Folder of the kit's ``<name>.yaml`` profile files.
PROFILES_DIR = Path(__file__).resolve().parent


def profile_names(folder: str | Path = PROFILES_DIR) -> list[str]:
    """Names of the profiles in ``folder`` (the kit's: ``["cpu", "cpu_paper_layout", "paper", "smoke"]``),
    sorted."""
    return sorted(p.stem for p in Path(folder).glob("*.yaml"))


def profile_path(profile: str | Path, folder: str | Path = PROFILES_DIR) -> Path:
    """The file of a profile: ``<folder>/<name>.yaml`` for a name, else the YAML path itself.

    Raises:
        ProfileError: no such profile or file.
    """
    if isinstance(profile, Profile):
        return profile.path
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


#: The key of a profile that names the profile it starts from (see the module docstring).
INHERITS = "inherits"

#: The top-level keys a profile may have, and the sections inside ``data:``: a misspelt one
#: (``trian:``) would otherwise be ignored while the command runs on the inherited or default one.
SECTIONS = ("description", "cell_timeout_s", INHERITS, "sequences", "data", "notebooks", "pretrain", "train",
            "prior", "finetune", "fitting", "networks")
DATA_SECTIONS = ("still",)


def read_profile(profile: str | Path, folder: str | Path = PROFILES_DIR) -> dict:
    """A profile's content: ``{section: settings}``, with the sections of the profile it
    ``inherits`` from (recursively) under its own.

    Raises:
        ProfileError: no such profile, an empty file, invalid YAML, not a mapping of sections, or
            an ``inherits:`` that names no profile or comes back to a file already read.
    """
    if isinstance(profile, Profile):
        return copy.deepcopy(dict(profile.sections))  # a reader may change its copy, never the run's
    return _read_inheriting(profile_path(profile, folder), folder, ())


class Profile(str):
    """A profile read once: the name or path it was given as, with its sections.

    It is that string (``Profile(...) == "cpu"``), so that run folders, records and messages built
    from it are those of the name; :func:`read_profile`, :func:`profile_section` and
    :func:`section_config` take their sections from it instead of the file. Make one with
    :func:`loaded`.

    Attributes:
        path: the profile's file.
        sections: ``{section: settings}``, the inherited ones merged in (:func:`read_profile`).
    """

    path: Path
    sections: dict

    def __new__(cls, given: str | Path, path: str | Path, sections: Mapping) -> Profile:
        self = super().__new__(cls, str(given))
        self.path = Path(path)
        self.sections = copy.deepcopy(dict(sections))
        return self

    def __reduce__(self):
        # pickled or deep-copied it is the plain string: a worker process reads the profile itself.
        # torch's weights_only loader refuses even this call of str, so a record that goes into a
        # checkpoint stores str(profile) (prior.build)
        return (str, (str(self),))

    @property
    def name(self) -> str:
        """The profile's name: its file's stem (``"cpu"``)."""
        return self.path.stem

    @property
    def digest(self) -> str:
        """SHA-256 of the sections read (inherited ones included): equal digests, equal profiles."""
        text = json.dumps(self.sections, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()


# written to YAML (manifests, records) as the plain string it is
yaml.SafeDumper.add_representer(Profile, yaml.representer.SafeRepresenter.represent_str)


def loaded(profile: str | Path, folder: str | Path = PROFILES_DIR) -> Profile:
    """A profile read now, to be passed down (a :class:`Profile` is returned as it is).

    Raises:
        ProfileError: as :func:`read_profile`.
    """
    if isinstance(profile, Profile):
        return profile
    path = profile_path(profile, folder)
    return Profile(profile, path, _read_inheriting(path, folder, ()))


def _read_inheriting(path: Path, folder: str | Path, seen: tuple[Path, ...]) -> dict:
    raw = _read_file(path)
    parent = raw.pop(INHERITS, None)
    if parent is None:
        return raw
    if not isinstance(parent, str):
        raise ProfileError(f"{path}: `{INHERITS}:` must name one profile (e.g. `{INHERITS}: cpu`), "
                           f"not {parent!r}; fix the file")
    beside = path.parent / (parent if parent.endswith((".yaml", ".yml")) else f"{parent}.yaml")
    parent_path = beside if beside.is_file() else profile_path(parent, folder)
    chain = (*seen, path.resolve())
    if parent_path.resolve() in chain:
        raise ProfileError(f"{path}: `{INHERITS}: {parent}` comes back to {parent_path}; a profile cannot "
                           "inherit from itself, fix the chain")
    return _merge(_read_inheriting(parent_path, folder, chain), raw)


def _merge(base: dict, over: Mapping) -> dict:
    """``over`` laid over ``base``: mappings merge key by key, anything else replaces."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, Mapping) and isinstance(out.get(k), Mapping) else v
    return out


def _read_file(path: Path) -> dict:
    """One YAML file's mapping of sections (its ``inherits:`` not resolved)."""
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
    _check_sections(raw, SECTIONS, path, "")
    if isinstance(raw.get("data"), dict):
        _check_sections(raw["data"], DATA_SECTIONS, path, "data: ")
    return raw


def _check_sections(raw: Mapping, known: tuple[str, ...], path: Path, parent: str) -> None:
    """Raise :class:`ProfileError` for a key of ``raw`` that is not one of ``known`` sections."""
    for key in raw:
        if key not in known:
            raise ProfileError(f"{path}: unknown section `{parent}{key}:`; "
                               f"{config_fields.unknown_hint(str(key), known)} (fix the file)")


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
    value = read_profile(profile, folder)
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


def section_where(profile: str | Path, section: str, folder: str | Path = PROFILES_DIR) -> str:
    """How messages name a section: ``"<file>, section `data: still:`"``."""
    return f"{profile_path(profile, folder)}, section `{': '.join(section.split('.'))}:`"


def section_config(profile: str | Path, section: str, cls, overrides: Mapping[str, Any] | None = None, *,
                   required: str | None = None, build=None, overrides_where: str = "options",
                   folder: str | Path = PROFILES_DIR):
    """A config dataclass from a profile section, then ``overrides``.

    The one way from a section to its config: the section (:func:`profile_section`) goes
    through ``config_fields.config_from``, so an unknown key names the closest known one and a
    refused value its field, both with the file and the section
    (:class:`~airpose_lib.errors.ProfileSettingError`); then ``overrides`` (a command's options)
    go on top, checked the same way and named ``overrides_where``. Missing keys keep the defaults.

    Args:
        profile: a profile name or the path of a profile YAML file.
        section: the section's key (``"data.still"`` is ``data: still:``).
        cls: the config dataclass, or a tuple of them for a section shared by several configs
            (each takes its own keys; a key several have, e.g. ``seed``, goes to each; returns a
            tuple then).
        overrides: settings on top of the section's (one ``cls`` only).
        required: as :func:`profile_section`.
        build: makes a config of checked values (default ``cls(**values)``; e.g. a
            ``from_dict`` that builds nested configs).
        overrides_where: how messages name ``overrides``.
        folder: where named profiles live.
    Raises:
        ProfileError: as :func:`profile_section`; ProfileSettingError: an unknown key or a bad value.
        ConfigError: the same in ``overrides``.
    """
    path = profile_path(profile, folder)
    values = profile_section(profile, section, required=required, folder=folder)
    where = section_where(path, section)
    if isinstance(cls, tuple):
        config_fields.check_keys(values, cls, where, ProfileSettingError)
        return tuple(config_from(c, {k: v for k, v in values.items() if k in config_fields.field_types(c)},
                                 where, build=build, error=ProfileSettingError) for c in cls)
    config = config_from(cls, values, where, build=build, error=ProfileSettingError)
    if overrides:
        config = config_from(cls, {**values, **overrides}, overrides_where, build=build)
    return config
