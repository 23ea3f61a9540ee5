"""Rewrite (or check) the generated result blocks of the README and the docs pages.

    python scripts/readme_results.py            # rewrite every block from its results/<profile>/
    python scripts/readme_results.py --check    # exit 1 when a page and its bundle disagree

A block is Table I (``<!-- results:<profile> -->``), the recordings' UAV2 in UAV1
(``<!-- recordings:<profile> -->``), the shipped networks' manifest (``<!-- zoo:<profile> -->``) or
the video route on known truth (``<!-- video:<profile> -->``);
:data:`BLOCKS` says which page holds which.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from airpose_lib.eval.readme_block import (
    block_markers,
    readme_block,
    recordings_block,
    replace_block,
    results_block,
    video_block,
)
from airpose_lib.paths import RunFolders
from airpose_lib.zoo import zoo_dir, zoo_table

ROOT = Path(__file__).resolve().parents[1]
#: (page, profile, kind): every generated block and the page it lives on.
BLOCKS = (("README.md", "cpu", "results"),
          ("docs/findings.md", "cpu_paper_layout", "results"),
          ("docs/recordings.md", "cpu", "recordings"),
          ("docs/model_zoo.md", "cpu", "zoo"),
          ("docs/own_videos.md", "demo", "video"))


def block(profile: str, kind: str) -> str:
    """The block of ``kind`` made from ``results/<profile>/``."""
    if kind == "zoo":
        opening, closing = block_markers(profile, kind)
        folder = zoo_dir(RunFolders(profile))
        return (f"{opening}\nThe `{profile}` profile's shipped networks (`{folder.relative_to(ROOT)}/manifest.yaml`; "
                f"`airpose zoo verify --profile {profile}` checks them):\n\n{zoo_table(folder)}\n{closing}")
    if kind == "video":
        made = video_block(profile)
        if made is None:
            raise SystemExit(f"results/{profile}/video/ has no known_truth.csv: make it with write_video_reference "
                             "(docs/own_videos.md)")
        return made
    made = results_block(profile) if kind == "results" else recordings_block(profile)
    if made is None:
        raise SystemExit(f"results/{profile}/recordings/ has no marker table (markers.csv): make it with "
                         "notebook 05 on recordings with markers")
    return made


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 on a difference")
    args = parser.parse_args(argv)
    differ = 0
    for page, profile, kind in BLOCKS:
        path = ROOT / page
        text, new = path.read_text(), block(profile, kind)
        if args.check:
            same = readme_block(text, profile, kind) == new
            differ += not same
            print(f"{page}: the {profile} {kind} block {'matches' if same else 'differs from'} results/{profile}/")
        else:
            path.write_text(replace_block(text, new, profile, kind))
            print(f"{page}: the {profile} {kind} block rewritten from results/{profile}/")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
