"""The HTML report of a reproduction: pages, figures, captions and the checks that fail it.

Built from hand-made executed notebooks and figures in a temporary run folder: nothing is executed.
"""
from __future__ import annotations

import base64
import io
import json

import nbformat
import pytest
import yaml
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output
from PIL import Image

from airpose_lib.cli import main
from airpose_lib.reproduce import load_catalog
from airpose_lib.reproduce.report import FIGURES_README, build_report, figure_captions, shrink_image


def _png(size=(300, 200), noise=False) -> bytes:
    img = Image.new("RGB", size, "white")
    if noise:  # a photograph-like image: JPEG wins
        img = Image.effect_noise(size, 60).convert("RGB")
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()


@pytest.fixture
def run(tmp_path):
    """A catalogue of two notebooks, their executed copies, figures, captions and report.json."""
    catalog = {"notebooks": [
        {"name": "00_first", "file": "00_first.ipynb", "reproduces": "Fig. 1", "figures": ["a.png", "t.csv"]},
        {"name": "01_second", "file": "01_second.ipynb", "reproduces": "Table I", "figures": ["b.png"]}]}
    (tmp_path / "catalog.yaml").write_text(yaml.safe_dump(catalog))
    (tmp_path / "README.md").write_text(
        "| figure | notebook | paper | how to read it |\n|---|---|---|---|\n"
        "| `a.png`, `t.csv` | `00_first` | **Fig. 1** | the first **figure** |\n"
        "| `b.{png,md}` | `01_second` | Table I | bars per `variant` |\n")
    run_dir, figures = tmp_path / "runs" / "smoke", tmp_path / "figures"
    (run_dir / "notebooks").mkdir(parents=True)
    figures.mkdir()
    for name in ("00_first", "01_second"):
        image = new_output("display_data", data={"image/png": base64.b64encode(_png((2400, 1600))).decode()})
        cell = new_code_cell("plot()", outputs=[image, new_output("stream", name="stdout", text="MPE 0.5 m\n")])
        nb = new_notebook(cells=[new_markdown_cell(f"# {name}"), cell])
        nbformat.write(nb, run_dir / "notebooks" / f"{name}.ipynb")
    (figures / "a.png").write_bytes(_png((2400, 1600)))
    (figures / "b.png").write_bytes(_png((500, 400), noise=True))
    (figures / "t.csv").write_text("x\n1\n")
    (run_dir / "report.json").write_text(json.dumps({
        "profile": "smoke", "description": "tiny", "kit_version": "0.1.0", "started_at": "2026-01-01T00:00:00",
        "wall_s": 12.5, "results": [{"name": "00_first", "status": "ok", "wall_s": 4.25},
                                    {"name": "01_second", "status": "ok", "wall_s": 8.25}]}))
    bundle = run_dir / "02_ablation_table" / "results"
    bundle.mkdir(parents=True)
    (bundle / "provenance.json").write_text(json.dumps({
        "git": {"commit": "0123abcd", "dirty": False}, "machine": {"cpu": "Test CPU", "cores": 2},
        "created_at": "2026-01-01", "command": "airpose reproduce --profile smoke", "wall_s": {"train": 3.0}}))
    return {"root": tmp_path, "run_dir": run_dir, "figures": figures, "out": tmp_path / "report",
            "kw": {"catalog_path": tmp_path / "catalog.yaml", "readme": tmp_path / "README.md"}}


def _build(run, **kw):
    return build_report("smoke", run_dir=run["run_dir"], figures_dir=run["figures"], out_dir=run["out"],
                        **run["kw"], **kw)


def test_report_has_an_index_and_one_page_per_notebook_in_catalogue_order(run):
    result = _build(run, max_image_px=400)
    assert result.ok, result.problems
    assert list(result.pages) == ["00_first", "01_second"]
    out = run["out"]
    index = (out / "index.html").read_text()
    for text in ("0123abcd", "Test CPU", "12.5 s", "4.2 s", "8.2 s", "train", "<strong>figure</strong>",
                 "<code>variant</code>", 'href="00_first.html"', 'src="figures/a.png"'):
        assert text in index, text
    assert index.index("00_first") < index.index("01_second")
    page = (out / "00_first.html").read_text()
    assert "MPE 0.5 m" in page and 'href="01_second.html"' in page and 'href="index.html"' in page
    assert "<style" not in page.split("</head>")[0] and 'rel="stylesheet"' in page  # one shared sheet
    # every image at most 400 px on its longer side; the noisy figure became a JPEG
    assert Image.open(out / "figures" / "a.png").size == (400, 267)
    assert (out / "figures" / "b.jpg").is_file() and not (out / "figures" / "b.png").exists()
    assert (out / "figures" / "t.csv").read_text() == "x\n1\n"
    assert result.total_bytes == sum(f.stat().st_size for f in out.rglob("*") if f.is_file())


def test_the_pages_name_no_folder_of_this_machine(run, monkeypatch):
    """The parameters cell's output folder and a printed cache file are named by their roots; the
    pages' images and links are left as they are."""
    monkeypatch.setenv("AIRPOSE_CACHE", str(run["root"] / "cache"))
    monkeypatch.setenv("AIRPOSE_RUNS", str(run["root"] / "runs"))
    path = run["run_dir"] / "notebooks" / "00_first.ipynb"
    nb = nbformat.read(path, as_version=4)
    prior = run["root"] / "cache" / "prior" / "smoke" / "vposer.pt"
    printed = new_output("stream", name="stdout", text=f"prior: kit ({prior}); table in /tmp/elsewhere/x/t.csv\n")
    nb.cells.insert(0, new_code_cell(f'output_dir = "{run["run_dir"] / "00_first"}"', outputs=[printed]))
    nbformat.write(nb, path)
    _build(run, max_image_px=400)
    page = (run["out"] / "00_first.html").read_text()
    assert str(run["root"]) not in page and "/tmp/elsewhere" not in page
    # as text the browser shows: a bare <cache> would be a tag it hides
    for text in ("&lt;runs&gt;/smoke/00_first", "&lt;cache&gt;/prior/smoke/vposer.pt", "&lt;abs&gt;/x/t.csv"):
        assert text in page, text
    assert "<cache>" not in page and "<abs>" not in page
    image = page.split("data:image/png;base64,")[1].split('"')[0]
    assert Image.open(io.BytesIO(base64.b64decode(image))).size == (400, 267)  # the image's bytes are whole


def test_an_error_output_a_missing_figure_and_a_missing_notebook_are_problems(run):
    path = run["run_dir"] / "notebooks" / "01_second.ipynb"
    nb = nbformat.read(path, as_version=4)
    nb.cells[1].outputs.append(new_output("error", ename="KeyError", evalue="'claim'", traceback=[]))
    nbformat.write(nb, path)
    (run["figures"] / "a.png").unlink()
    result = _build(run)
    assert result.problems == ["00_first: figure a.png missing from " + str(run["figures"]),
                               "01_second: execution error in cell 1: KeyError: 'claim'"]
    assert "KeyError" in (run["out"] / "index.html").read_text()  # the report is written all the same
    (run["run_dir"] / "notebooks" / "00_first.ipynb").unlink()
    assert any("00_first: no executed notebook" in p for p in _build(run).problems)


def test_a_size_cap_and_a_missing_caption_are_problems(run):
    (run["root"] / "README.md").write_text("| figure | notebook | paper | how |\n|---|---|---|---|\n")
    problems = _build(run, max_bytes=1000).problems
    assert "00_first: figure a.png has no caption in " + str(run["root"] / "README.md") in problems
    assert any(p.startswith("the report is ") and "over the cap of 0.0 MB" in p for p in problems)


def test_cli_exit_status_and_messages(run, capsys, monkeypatch):
    import airpose_lib.reproduce.report as report

    monkeypatch.setattr(report, "CATALOG_PATH", run["kw"]["catalog_path"])
    monkeypatch.setattr(report, "FIGURES_README", run["kw"]["readme"])
    args = ["report", "--profile", "smoke", "--runs", str(run["run_dir"].parent), "--figures", str(run["figures"]),
            "--out", str(run["out"])]
    assert main(args) == 0
    assert "2 notebook pages" in capsys.readouterr().out
    (run["figures"] / "b.png").unlink()
    assert main(args) == 1
    assert "01_second: figure b.png missing" in capsys.readouterr().err
    assert main(["report", "--profile", "smoke", "--runs", str(run["root"] / "nowhere")]) == 2
    assert "no executed notebooks" in capsys.readouterr().err
    assert main([*args[:-1], str(run["figures"])]) == 2  # --out: a folder that is not a report is kept
    assert "holds no report" in capsys.readouterr().err and (run["figures"] / "a.png").is_file()


def test_cli_reads_the_run_of_an_own_profile_file_by_its_name(run, capsys, monkeypatch, tmp_path):
    import airpose_lib.reproduce.report as report

    monkeypatch.setattr(report, "CATALOG_PATH", run["kw"]["catalog_path"])
    monkeypatch.setattr(report, "FIGURES_README", run["kw"]["readme"])
    run["run_dir"].rename(run["run_dir"].with_name("mine"))  # what `reproduce --profile mine.yaml` makes
    own = tmp_path / "elsewhere" / "mine.yaml"
    own.parent.mkdir()
    own.write_text("inherits: smoke\n")
    assert main(["report", "--profile", str(own), "--runs", str(run["run_dir"].parent), "--figures",
                 str(run["figures"]), "--out", str(run["out"])]) == 0
    assert "2 notebook pages" in capsys.readouterr().out


def test_shrink_keeps_line_art_png_and_small_images_as_they_are():
    data, mime = shrink_image(_png((100, 50)), 400)
    assert mime == "image/png" and Image.open(io.BytesIO(data)).size == (100, 50)


def test_the_readme_captions_every_catalogue_figure():
    captions = figure_captions(FIGURES_README)
    missing = [f for e in load_catalog() for f in e.figures if f not in captions]
    assert missing == []
    assert "Table I" in captions["table1_ablation.png"]["paper"]


def test_write_reference_builds_the_capped_report_only_after_a_whole_run(run, capsys, monkeypatch, tmp_path):
    """`airpose reproduce --write-reference`: results/<profile>/report/ from this run, size-capped."""
    import airpose_lib.eval.reference as reference
    import airpose_lib.reproduce as reproduce
    import airpose_lib.reproduce.report as report
    from airpose_lib.cli.reproduce import _write_reference_report
    from airpose_lib.reproduce import NotebookResult, RunReport, load_catalog

    catalog = load_catalog(run["kw"]["catalog_path"])
    monkeypatch.setattr(reproduce, "load_catalog", lambda: catalog)
    monkeypatch.setattr(report, "CATALOG_PATH", run["kw"]["catalog_path"])
    monkeypatch.setattr(report, "FIGURES_README", run["kw"]["readme"])
    monkeypatch.setattr(reference, "reference_dir", lambda folders: tmp_path / "results" / folders.name)
    done = RunReport("smoke", "", "0.1.0", "python3", "", str(run["run_dir"]), str(run["figures"]),
                     results=[NotebookResult("01_second", "01_second.ipynb", status="ok")])
    assert _write_reference_report(done) == 0
    assert "not written" in capsys.readouterr().out and not (tmp_path / "results").exists()
    done.results.insert(0, NotebookResult("00_first", "00_first.ipynb", status="ok"))
    assert _write_reference_report(done) == 0
    out = tmp_path / "results" / "smoke" / "report"
    assert (out / "index.html").is_file()
    assert max(Image.open(out / "figures" / "a.png").size) == report.REFERENCE_MAX_IMAGE_PX
    monkeypatch.setattr(report, "REFERENCE_MAX_BYTES", 1000)
    assert _write_reference_report(done) == 1
    assert "over the cap of 0.0 MB" in capsys.readouterr().err
