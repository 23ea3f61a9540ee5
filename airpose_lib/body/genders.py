"""The three body models and the integer codes a sample stores for them (``sample['gender']``).

One contract for the whole kit: the kit's data and sequence generators write the codes, the
official loaders translate the release's names into them, the losses and evaluations turn them
back into a model name. Imports nothing, so the light modules (``data.still.scene``) may use it.
"""
from __future__ import annotations

__all__ = ["GENDERS", "GENDER_CODES", "GENDER_NAMES"]

#: The body models, in code order.
GENDERS: tuple[str, ...] = ("neutral", "male", "female")
#: Model name -> code: 0 neutral, 1 male, 2 female.
GENDER_CODES: dict[str, int] = {name: code for code, name in enumerate(GENDERS)}
#: Code -> model name (the inverse of :data:`GENDER_CODES`).
GENDER_NAMES: dict[int, str] = dict(enumerate(GENDERS))
