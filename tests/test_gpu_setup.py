"""The GPU route (docs/gpu.md), as far as it runs without a GPU: the set-up that keeps
the user's torch refuses an environment without one, and the documented commands parse."""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_keep_torch_refuses_an_environment_without_torch(tmp_path):
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(tmp_path / "venv")], check=True)
    env = dict(os.environ, AIRPOSE_KEEP_TORCH="1", AIRPOSE_VENV=str(tmp_path / "venv"))
    proc = subprocess.run(["bash", str(REPO / "scripts" / "setup.sh")], env=env, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 1 and "has no torch to keep" in proc.stderr, proc.stderr


def test_the_gpu_commands_of_the_docs_parse():
    from airpose_lib.cli import build_parser

    section = (REPO / "docs" / "gpu.md").read_text()
    commands = [" ".join(c.split("\\\n")) for c in re.findall(r"^\.venv/bin/(?:airpose|torchrun) .*?(?<!\\)$",
                                                             section, flags=re.M | re.S)]
    parsed = 0
    for command in commands:
        argv = shlex.split(command.split("#")[0])
        if argv[0].endswith("torchrun"):
            argv = argv[argv.index("airpose_lib.cli") + 1:]
        else:
            argv = argv[1:]
        args = build_parser().parse_args(argv)
        parsed += 1
        if args.command == "train":
            assert args.device == "cuda" and any(s.startswith("precision=") for s in args.set)
    assert parsed == 3  # backbone import, one GPU, torchrun
