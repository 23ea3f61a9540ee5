"""Rewrite (or check) the README's result block from a committed reference bundle.

    python scripts/readme_results.py            # rewrite README.md's cpu block from results/cpu/
    python scripts/readme_results.py --check    # exit 1 when the README and results/cpu/ disagree
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from airpose_lib.eval.readme_block import readme_block, replace_block, results_block

README = Path(__file__).resolve().parents[1] / "README.md"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 on a difference")
    args = parser.parse_args(argv)
    text, block = README.read_text(), results_block(args.profile)
    if args.check:
        same = readme_block(text, args.profile) == block
        print(f"{README}: the {args.profile} block {'matches' if same else 'differs from'} results/{args.profile}/")
        return 0 if same else 1
    README.write_text(replace_block(text, block, args.profile))
    print(f"{README}: the {args.profile} block rewritten from results/{args.profile}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
