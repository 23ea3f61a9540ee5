"""What the real-data experiment runs on: the recordings (the profile's generated ones or the
official release's), the networks given instead of trained (the official ones, or a profile's
shipped set), whether the field recordings run too, and the pose prior.
"""
from __future__ import annotations

from pathlib import Path

from airpose_lib.assets import resolve_data_source
from airpose_lib.data.official.real import load_official_real
from airpose_lib.errors import ConfigError
from airpose_lib.prior import load_prior
from airpose_lib.prior.build import ensure_prior
from airpose_lib.train.official import find_official_checkpoint

from .configs import KitConfigs
from .recording_cache import file_stamp
from .shipped import NetworksConfig, shipped_networks

__all__ = ["OFFICIAL_REAL_CHECKPOINTS", "official_recordings", "official_networks", "networks_for", "recordings_for",
           "runs_field", "recording_prior"]

#: Folders of the official real-data (fine-tuned on person 1) checkpoints (data_manifests/official_checkpoints.yaml).
OFFICIAL_REAL_CHECKPOINTS = {"Baseline": "hmr_real_ckpt", "AirPose": "copenet_twoview_real_ckpt"}


def official_recordings(root: str | Path) -> dict:
    """The official real-data release as the experiment's recordings: person 1 (frames 0-6999,
    fine-tuning) and person 2 (frames 8000-14999, test), without ground truth."""
    return {"person1": load_official_real(root, person=1), "person2": load_official_real(root, person=2)}


def official_networks(checkpoints_root: str | Path) -> dict[str, Path]:
    """The authors' networks for the experiment's methods: the synthetic-data checkpoints of
    Baseline and AirPose (pre-trained) and their real-data fine-tuned ones (``hmr_real_ckpt``,
    ``copenet_twoview_real_ckpt``)."""
    root = Path(checkpoints_root)
    nets = {"Baseline (pre-trained)": find_official_checkpoint(root, "baseline"),
            "AirPose (pre-trained)": find_official_checkpoint(root, "airpose")}
    for method, folder in OFFICIAL_REAL_CHECKPOINTS.items():
        found = sorted((root / folder).glob("**/*.ckpt"))
        if not found:
            raise FileNotFoundError(f"no .ckpt under {root / folder}; unpack {folder}.zip of the official release "
                                    "there (data_manifests/official_checkpoints.yaml)")
        nets[method] = found[-1]
    return nets


def networks_for(source, networks: NetworksConfig | None = None, field: bool = False) -> dict[str, Path] | None:
    """The networks the experiment runs instead of training its own: the official ones when the
    data source is official and ``official_checkpoints`` is present (see :func:`official_networks`),
    the shipped set of a profile on shipped networks (its ``networks:`` section; ``field``: those
    fine-tuned on the field recordings), else None (the kit trains and fine-tunes its own)."""
    if getattr(source, "source", "generated") != "official":
        shipped = shipped_networks(networks)
        return None if shipped is None else shipped.recordings(field)

    ckpts = resolve_data_source("official", needs=["official_checkpoints"])
    if ckpts.source != "official":
        print(ckpts.message.replace("the kit's generated data", "the kit's own networks, fine-tuned here"))
        return None
    return official_networks(ckpts.roots["official_checkpoints"])


def recordings_for(source) -> dict | None:
    """Recordings for a resolved data source (:func:`airpose_lib.assets.resolve_data_source`):
    None (the profile's generated recordings) or the official release's two persons."""
    if getattr(source, "source", "generated") != "official":
        return None
    return official_recordings(source.roots["official_real"])


def runs_field(source, configs: KitConfigs, field: bool | None = None) -> bool:
    """Whether the real-data notebooks also run the profile's field recordings.

    Args:
        source: the resolved data source (:func:`recordings_for`'s).
        configs: the profile's configs.
        field: the notebook's parameter; None: when the recordings are generated and the profile
            has field recordings (``sequences: field_recordings:``).
    Raises:
        ConfigError: ``field`` is true with the official recordings (they are field footage) or
            with a profile without field recordings.
    """
    generated = getattr(source, "source", "generated") != "official"
    has = bool(configs.field_sequences)
    if field is None:
        return generated and has
    if field and not (generated and has):
        raise ConfigError(f"field=True needs the generated recordings of a profile with `sequences: field_recordings:` "
                          f"({'the official recordings are field footage' if not generated else configs.label + ' has none'}); "
                          "set field to None or False")
    return bool(field)


def recording_prior(configs: KitConfigs, progress: bool = False):
    """The pose prior of the experiment: VPoser V02_05 when it is installed (``vposer_v02_05``
    asset, e.g. ``$AIRPOSE_VPOSER_DIR``), else the profile's kit prior (trained on first use).

    Returns:
        ``(prior, info)``: the :class:`~airpose_lib.prior.VPoser` and ``{"source": "vposer" | "kit",
        "file", "stamp", "message"}`` (the message says which prior and why).
    """
    found = resolve_data_source("official", needs=["vposer_v02_05"])
    if found.source == "official":
        prior, prov = load_prior("vposer", found.roots["vposer_v02_05"], return_provenance=True)
        file = Path(prov["file"])
        msg = f"Pose prior: VPoser V02_05 ({file}), as the paper."
        source = "vposer"
    else:
        shipped = shipped_networks(configs.networks)
        file = shipped.prior if shipped is not None else ensure_prior(configs.prior, progress=progress)
        prior = load_prior("kit", file)
        msg = (f"Pose prior: the kit's VPoser-architecture prior ({file}); VPoser V02_05 is not installed "
               "(data_manifests/vposer_v02_05.yaml says how to get it; it is then used automatically).")
        source = "kit"
    return prior, {"source": source, "file": str(file), "stamp": file_stamp(file), "message": msg}
