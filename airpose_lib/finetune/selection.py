r"""Model selection for fine-tuning: which checkpoint of a run is kept.

The paper (Sec. III-C, on its loss weights): "even though the overall training and validation
loss keep going down, the model can overfit to some loss components. In such cases, we stop the
training once the model starts overfitting on any loss component." The kit reads this as:

``first_overfit`` (default, the paper's rule)
    A loss component ``c`` *starts overfitting* between two selection points ``k-1`` and ``k``
    when its value on the held-out frames rises while its value on the training frames falls
    (both measured the same way: eval mode, every frame). The kept checkpoint is the last one
    before the first such event, i.e. where the training would have stopped; with no such event,
    the last one. Only the components with a non-zero weight count.
``min_heldout_j2d``
    The checkpoint with the lowest held-out 2D loss (ties: the earliest). The kit's rule before
    the paper's was implemented; kept for comparison.

Both read only the tuning person's frames. A selection row is a mapping with ``step`` and, for
every component ``c``, ``heldout_<c>`` and ``train_<c>``; rows are in step order.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from airpose_lib.errors import ConfigError

__all__ = ["SELECTION_RULES", "Selection", "overfitting_terms", "select_step"]

SELECTION_RULES = ("first_overfit", "min_heldout_j2d")


@dataclass(frozen=True)
class Selection:
    """The choice of a rule over the rows so far.

    Attributes:
        step: the kept checkpoint's step (None without rows).
        overfit_step: ``first_overfit`` only: the selection point at which a component first
            started overfitting (None: none has yet).
        overfit_terms: the components that started overfitting there.
    """

    step: int | None
    overfit_step: int | None = None
    overfit_terms: list[str] = field(default_factory=list)


def overfitting_terms(prev: Mapping[str, float], cur: Mapping[str, float], terms: Sequence[str]) -> list[str]:
    """Components whose held-out value rose from ``prev`` to ``cur`` while their training value fell."""
    return [t for t in terms
            if cur[f"heldout_{t}"] > prev[f"heldout_{t}"] and cur[f"train_{t}"] < prev[f"train_{t}"]]


def select_step(rows: Sequence[Mapping[str, float]], rule: str, terms: Sequence[str]) -> Selection:
    """Apply a selection rule (:data:`SELECTION_RULES`) to the selection rows of a run.

    Args:
        rows: selection points in step order (see the module docstring).
        rule: ``first_overfit`` or ``min_heldout_j2d``.
        terms: the loss components that count (``first_overfit``).
    """
    if rule not in SELECTION_RULES:
        raise ConfigError(f"unknown selection rule {rule!r}; use one of {', '.join(SELECTION_RULES)}")
    if not rows:
        return Selection(None)
    if rule == "min_heldout_j2d":
        best = min(range(len(rows)), key=lambda i: (rows[i]["heldout_j2d"], i))
        return Selection(int(rows[best]["step"]))
    for prev, cur in zip(rows[:-1], rows[1:]):
        hit = overfitting_terms(prev, cur, terms)
        if hit:
            return Selection(int(prev["step"]), int(cur["step"]), hit)
    return Selection(int(rows[-1]["step"]))
