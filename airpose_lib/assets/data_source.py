"""Which data a notebook runs on: the kit's generated data, or the official assets when present.

Notebooks take a ``data_source`` parameter (``"generated"`` or ``"official"``) and call::

    src = resolve_data_source(data_source, needs=["official_real", "official_checkpoints"])
    print(src.message)
    if src.source == "official": ...  # src.roots["official_real"] is the folder

Asking for ``"official"`` when an asset is missing is not an error: the notebook falls back to the
generated data and the message names the missing asset and how to get it, so a fresh machine
still runs every notebook end to end.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from airpose_lib.errors import ConfigError

from .verify import VerifyReport, verify

__all__ = ["DATA_SOURCES", "DataSource", "resolve_data_source"]

DATA_SOURCES = ("generated", "official")


@dataclass(frozen=True)
class DataSource:
    """``source``: the data to use (``generated`` or ``official``); ``roots``: asset name -> folder
    (official only); ``reports``: the verification of every needed asset (official requests)."""

    requested: str
    source: str
    message: str
    roots: dict[str, Path] = field(default_factory=dict)
    reports: tuple[VerifyReport, ...] = ()

    @property
    def fell_back(self) -> bool:
        """True when official data was asked for but the generated data is used."""
        return self.requested != self.source


def resolve_data_source(requested: str, needs: Sequence[str], *, checksums: bool = False,
                        manifests: str | Path | None = None) -> DataSource:
    """Decide between generated and official data.

    Args:
        requested: ``"generated"`` or ``"official"``.
        needs: the assets an official run needs (manifest names, e.g. ``["official_real"]``).
        checksums: also compare SHA-256 where known (slow on large data; sizes and presence are
            always checked).
        manifests: manifests folder (default: the checkout's ``data_manifests/``).
    Returns:
        the :class:`DataSource`; its ``message`` is meant to be printed by the notebook.
    Raises:
        ValueError: ``requested`` is not one of :data:`DATA_SOURCES`.
        AssetError: a name in ``needs`` has no manifest (a bug in the caller, not a missing download).
    """
    if requested not in DATA_SOURCES:
        raise ConfigError(f"data source must be one of {DATA_SOURCES}, got {requested!r}")
    if requested == "generated":
        return DataSource(requested, "generated", "Data source: the kit's generated data (data_source='generated').")
    reports = tuple(verify(name, checksums=checksums, manifests=manifests) for name in needs)
    missing = [r for r in reports if not r.ok]
    if not missing:
        where = "; ".join(f"{r.name} in {r.root} (from {r.location.detail})" for r in reports)
        return DataSource(requested, "official", f"Data source: official data - {where}.",
                          {r.name: r.root for r in reports}, reports)
    names = ", ".join(r.name for r in missing)
    parts = [f"Data source: official data requested, but {names} "
             f"{'is' if len(missing) == 1 else 'are'} not available - falling back to the kit's generated "
             f"data. To use the official data:"]
    for r in missing:
        parts.append(r.text())
    return DataSource(requested, "generated", "\n".join(parts), {}, reports)
