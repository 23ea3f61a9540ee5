"""Training and fitting losses."""

from .robust import geman_mcclure

__all__ = ["geman_mcclure"]
