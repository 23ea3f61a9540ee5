"""No hand-typed measured number in a notebook's prose.

A number typed into a markdown cell from an earlier run contradicts the outputs as soon as the run
differs. Results are printed by code cells from the run's own tables (for notebook 02,
``airpose_lib.eval.ablation.ablation_findings``). The check is a pattern: a decimal number, or a
number with a unit (m, mm, deg, %, px, s, ms, fps ...), in a markdown sentence fails the test unless

* the sentence labels it as the paper's (it says "paper" or cites a section, "Sec. ..."), or
* it is one of the kit's settings listed in :data:`SETTINGS` (inputs of every run, not results).

Numbers inside code spans (`beta_std = 1`) are names of settings and are not checked.
"""
from __future__ import annotations

import re
from pathlib import Path

import nbformat
import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))

#: A measured-looking value: a decimal number, or a number followed by a unit.
MEASURED = re.compile(r"(?<![\w.])\d+\.\d+(?![\w.])"
                      r"|(?<![\w.])\d+(?:,\d{3})*\s*(?:mm|cm|m|°|deg|degrees?|%|px|ms|s|fps|Mbps)(?!\w)")
#: A sentence that says its numbers are the paper's.
PAPER = re.compile(r"\bpaper\b|\bSec\b", re.IGNORECASE)
_ABBREVIATIONS = re.compile(r"\b(Sec|Fig|e\.g|i\.e|cf|vs)\.\s")

#: The allow-list of settings: phrases (whitespace as in one line) that state a value the kit is
#: run with, the same in every run. Each must occur in its notebook, so a stale entry fails too.
SETTINGS: dict[str, tuple[str, ...]] = {
    "01_synthetic_data": ("(projected joints $\\pm$ 20 px) and a 200 px margin",),
    "02_ablation_table": ("interval = 95 % paired bootstrap", "(one reference seed: 10 % of its value)"),
    "03_trajectories": ("the detections $\\pm$ 120 px in the network's camera (20 px plus half of the 0-200 px "
                        "training enlargement",
                        "With a tight box (detections $\\pm$ 20 px)", "OpenPose $\\pm$ 50 px at 1920x1080"),
    "05_airpose_plus": ("Its 95 % interval comes from a block bootstrap over 1 s blocks",),
    "06_online_runtime": ("A 20 s run", "with 20 % of the packets lost", "caps the rate at 50 Mbps and adds 2-5 ms",
                          "killed after 2 s"),
}


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _sentences(markdown: str) -> list[str]:
    """The sentences of a markdown cell: split into paragraphs and list items, then at sentence ends
    (not after "Sec." or "e.g."); code spans removed, math kept without its dollar signs."""
    out = []
    for block in re.split(r"\n\s*\n|\n(?=\s*(?:[*-]|\d+\.)\s)", markdown):
        # an abbreviation's full stop becomes a one-dot leader, which does not end a sentence
        text = _ABBREVIATIONS.sub(lambda m: m.group(1) + "\u2024 ", _one_line(block))
        text = re.sub(r"`[^`]*`", "", text).replace("$", "")
        out += [s for s in re.split(r"(?<=[.!?])\s+(?=[A-Z*(])", text) if s]
    return out


def measured_values(markdown: str, settings: tuple[str, ...] = ()) -> list[tuple[str, list[str]]]:
    """``(sentence, values)`` for each sentence of ``markdown`` that states a measured-looking value
    and does not label it as the paper's; phrases of ``settings`` are left out first."""
    text = _one_line(markdown) if settings else markdown
    for phrase in settings:
        text = text.replace(phrase, "")
    return [(s, hits) for s in _sentences(text) if (hits := MEASURED.findall(s)) and not PAPER.search(s)]


def _markdown(path: Path) -> dict[int, str]:
    """Cell index -> source of each markdown cell."""
    return {i: c.source for i, c in enumerate(nbformat.read(path, as_version=4).cells) if c.cell_type == "markdown"}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_markdown_states_no_measured_value(path):
    settings = SETTINGS.get(path.stem, ())
    found = [f"cell {i}: {values} in {sentence[:120]!r}"
             for i, source in _markdown(path).items()
             for sentence, values in measured_values(source, tuple(p for p in settings if p in _one_line(source)))]
    assert not found, (f"{path.name} types measured values into its prose; print them from the run's tables "
                       f"in a code cell (or label them as the paper's, or list a setting in SETTINGS):\n"
                       + "\n".join(found))


@pytest.mark.parametrize("stem", sorted(SETTINGS))
def test_every_allowed_setting_is_in_its_notebook(stem):
    text = " ".join(_one_line(s) for s in _markdown(NOTEBOOKS[0].parent / f"{stem}.ipynb").values())
    assert [p for p in SETTINGS[stem] if p not in text] == []


@pytest.mark.parametrize("markdown, flagged", [
    ("AirPose reaches MPE 0.78 m on this split.", True),                       # a decimal with a unit
    ("The regressor's MPJPE fell by 22 mm.", True),                            # an integer with a unit
    ("The heading is right on 66 % of the crops.", True),
    ("The paper's AirPose MPE is 0.15 m.", False),                             # labelled as the paper's
    ("Cameras about 10 m away (Sec. IV-A).", False),                           # cites the paper
    ("Set `beta_std = 1.0` in the profile.", False),                           # a setting's name in code
    ("The 22 body joints over 2,000 steps.", False),                           # counts, no unit
    ("The paper's Table I. Our run: 1.13 m.", True),                           # the label is per sentence
])
def test_the_pattern(markdown, flagged):
    assert bool(measured_values(markdown)) is flagged
