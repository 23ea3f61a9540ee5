"""The data package's names: each entry point is written once, with the module that defines it
(``airpose_lib.data`` and ``airpose_lib.data.sequences``), and importing the packages or the
recording reader stays light (no torch, no VTK)."""
from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest


@pytest.mark.parametrize("package", ["airpose_lib.data", "airpose_lib.data.sequences"])
def test_every_exported_name_is_the_object_of_its_module(package):
    pkg = importlib.import_module(package)
    assert pkg.__all__ == sorted(pkg._EXPORTS)
    for name, module in pkg._EXPORTS.items():
        mod = importlib.import_module(f"{package}.{module}")
        assert getattr(pkg, name) is mod.__dict__[name], f"{package}.{name} is not {mod.__name__}.{name}"
    with pytest.raises(AttributeError, match="no attribute 'look_at_extrinsics'"):
        pkg.look_at_extrinsics  # noqa: B018 - a module's other names are not searched for


def test_packages_and_the_recording_reader_import_no_torch():
    code = ("import sys\nimport airpose_lib.data, airpose_lib.data.sequences, airpose_lib.data.still, "
            "airpose_lib.data.official\nfrom airpose_lib.data.sequences.reader import load_sequence\n"
            "print('HEAVY', [m for m in ('torch', 'smplx', 'pyvista', 'vtk', 'cv2') if m in sys.modules])")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                         cwd=Path(__file__).resolve().parents[1])
    assert "HEAVY []" in res.stdout, res.stdout + res.stderr
