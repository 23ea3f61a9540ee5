"""Rewrite (or check) the README's result blocks from a committed reference bundle.

    python scripts/readme_results.py            # rewrite README.md's cpu blocks from results/cpu/
    python scripts/readme_results.py --check    # exit 1 when the README and results/cpu/ disagree

The blocks: Table I (``<!-- results:<profile> -->``) and, where the README has one and the bundle
has the marker tables, the recordings' UAV2 in UAV1 (``<!-- recordings:<profile> -->``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from airpose_lib.eval.readme_block import readme_block, recordings_block, replace_block, results_block

README = Path(__file__).resolve().parents[1] / "README.md"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 on a difference")
    args = parser.parse_args(argv)
    text = README.read_text()
    blocks = {"results": results_block(args.profile)}
    if readme_block(text, args.profile, "recordings") is not None:
        blocks["recordings"] = recordings_block(args.profile)
        if blocks["recordings"] is None:
            print(f"{README} has a recordings block for {args.profile}, but results/{args.profile}/recordings/ "
                  "has no marker table (markers.csv): make it with notebook 05 on recordings with markers",
                  file=sys.stderr)
            return 1
    if args.check:
        same = all(readme_block(text, args.profile, kind) == block for kind, block in blocks.items())
        print(f"{README}: the {args.profile} blocks {'match' if same else 'differ from'} results/{args.profile}/")
        return 0 if same else 1
    for kind, block in blocks.items():
        text = replace_block(text, block, args.profile, kind)
        print(f"{README}: the {args.profile} {kind} block rewritten from results/{args.profile}/")
    README.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
