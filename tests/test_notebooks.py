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


# -- the set-up helper ------------------------------------------------------------------------------
def test_setup_notebook_fills_parameters_and_records_the_source(monkeypatch, tmp_path, capsys):
    from airpose_lib import paths
    from airpose_lib.reproduce import setup_notebook

    monkeypatch.setenv(paths.RUNS_ENV, str(tmp_path))
    ctx = setup_notebook("02_ablation_table", "cpu", seeds=None, train_workers=None, n_qualitative=5,
                         record={"variants": ["airpose"]})
    assert ctx.seeds == [123, 124, 125] and ctx.train_workers == 2 and ctx.n_qualitative == 5
    assert ctx.out == tmp_path / "cpu" / "02_ablation_table" and ctx.out.is_dir() and ctx.runs == tmp_path
    assert ctx.figures == paths.figures_root() / "cpu"
    assert not ctx.official and ctx.params == {"notebook": "02_ablation_table", "profile": "cpu",
                                               "data_source": "generated", "seeds": [123, 124, 125],
                                               "train_workers": 2, "n_qualitative": 5, "variants": ["airpose"]}
    assert "generated data" in capsys.readouterr().out
    with pytest.raises(AttributeError, match="no parameter"):
        _ = ctx.backbone


def test_setup_notebook_falls_back_to_generated_data_and_says_why(monkeypatch, tmp_path, capsys):
    from airpose_lib import paths
    from airpose_lib.reproduce import setup_notebook

    monkeypatch.setenv(paths.RUNS_ENV, str(tmp_path))
    monkeypatch.setenv("AIRPOSE_OFFICIAL_REAL_DIR", str(tmp_path / "nothing here"))
    ctx = setup_notebook("03_trajectories", "smoke", data_source="official", needs=["official_real"])
    assert ctx.source.requested == "official" and not ctx.official and ctx.params["data_source"] == "generated"
    assert "falling back" in capsys.readouterr().out
    ctx = setup_notebook("07_recording_3d", "smoke", data_source="official", generated_only="no true cameras")
    assert not ctx.official and "no true cameras" in capsys.readouterr().out
