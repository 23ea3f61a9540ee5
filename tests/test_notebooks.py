"""The notebooks stay thin: a parameters cell, one set-up call, no function or class definitions,
and no outputs in git (what ``nbstripout`` leaves)."""
from __future__ import annotations

import ast
from pathlib import Path

import nbformat
import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def _code_cells(nb) -> list:
    return [c for c in nb.cells if c.cell_type == "code"]


def _tree(source: str) -> ast.Module:
    # IPython magics and shell escapes are not Python
    return ast.parse("\n".join(line for line in source.splitlines() if not line.lstrip().startswith(("%", "!"))))


def test_there_are_notebooks():
    assert len(NOTEBOOKS) >= 8


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_has_one_parameters_cell_first(path):
    code = _code_cells(nbformat.read(path, as_version=4))
    tagged = [i for i, c in enumerate(code) if "parameters" in c.metadata.get("tags", [])]
    assert tagged == [0], f"{path.name}: the first code cell, and only it, is tagged 'parameters'"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_defines_no_functions_or_classes(path):
    for i, cell in enumerate(_code_cells(nbformat.read(path, as_version=4))):
        for node in ast.walk(_tree(cell.source)):
            assert not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)), \
                f"{path.name} code cell {i}: defines {node.name!r}; move it to the library"
            if isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Lambda):
                raise AssertionError(f"{path.name} code cell {i}: a lambda bound to a name is a function")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_set_up_in_one_call(path):
    code = _code_cells(nbformat.read(path, as_version=4))
    calls = [i for i, c in enumerate(code) for node in ast.walk(_tree(c.source))
             if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "setup_notebook"]
    assert calls == [1], f"{path.name}: setup_notebook is called once, in the cell after the parameters"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_has_no_outputs(path):
    for i, cell in enumerate(_code_cells(nbformat.read(path, as_version=4))):
        assert cell.outputs == [] and cell.execution_count is None, f"{path.name} code cell {i} has outputs"
