"""The committed results name no folder of the machine that made them (``paths.portable``): every
text file under ``results/`` and every string a ``.pt`` file there embeds (a backbone's
``meta_json``, a shipped network's config and fine-tuning record, the prior's provenance)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
import torch

RESULTS = Path(__file__).resolve().parents[1] / "results"
TEXT_SUFFIXES = {".json", ".md", ".csv", ".yaml", ".yml", ".html", ".txt"}
#: What an absolute path of a machine starts with (Linux, macOS, Windows).
MACHINE_PATH = re.compile(r"/work/|/root/|/home/|/tmp/|/Users/|C:\\")

def _strings(value):
    """Every str inside a loaded torch file (dict keys and values, lists, tuples)."""
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _strings(k)
            yield from _strings(v)
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _strings(v)


def _leaks(path: Path) -> list[str]:
    """The machine paths a file under results/ names (a few, to show)."""
    if path.suffix in TEXT_SUFFIXES:
        texts = [path.read_text(errors="replace")]
    elif path.suffix == ".pt":
        texts = list(_strings(torch.load(path, map_location="cpu", weights_only=True)))
    else:
        return []
    found = []
    for text in texts:
        found += [text[max(m.start() - 20, 0):m.end() + 40] for m in MACHINE_PATH.finditer(text)]
    return found[:3]


def _files() -> list[Path]:
    return sorted(p for p in RESULTS.rglob("*") if p.is_file() and (p.suffix in TEXT_SUFFIXES or p.suffix == ".pt"))


def test_the_results_name_no_folder_of_the_machine_that_made_them():
    if not RESULTS.is_dir():
        pytest.skip("no results/ in this copy of the kit")
    leaking = {}
    for path in _files():
        name = path.relative_to(RESULTS).as_posix()
        if found := _leaks(path):
            leaking[name] = found
    assert not leaking, ("files under results/ name a machine's folders (write them through "
                         "airpose_lib.paths.portable): " + "; ".join(f"{k}: {v}" for k, v in leaking.items()))
