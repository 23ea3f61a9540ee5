"""A static HTML report of a reproduction: the executed notebooks and the collected figures.

``airpose report --profile P`` reads what ``airpose reproduce --profile P`` left behind:

* ``<runs>/<P>/notebooks/*.ipynb``: the executed notebooks, with their outputs;
* ``<runs>/<P>/report.json``: status and wall time of each notebook (:class:`~.runner.RunReport`);
* ``<runs>/<P>/02_ablation_table/results/provenance.json``: the run's git commit, machine and
  training wall times, as notebook 02 recorded them (:mod:`airpose_lib.eval.reference`);
* ``figures/<P>/``: the figures the catalogue lists (``catalog.yaml``), with their captions in
  ``figures/README.md``;

and writes a folder a browser opens offline (``<runs>/<P>/report/`` unless told otherwise):
``index.html`` (the provenance, the notebooks with their wall times, every figure with its
caption), one page per notebook in the catalogue's (the paper's) order, made by nbconvert's
``HTMLExporter``, and ``figures/``. Every image, in the pages and in ``figures/``, is downscaled
to at most ``max_image_px`` on its longer side (a photographic one is stored as JPEG when that
halves it), so that a committed report stays small.

A notebook that is missing, a page with an error output, or a catalogue figure that is missing
(from ``figures/<P>/`` or from the captions) is a :class:`ReportProblem`: the report is still
written (the failing page shows its traceback), and :func:`build_report` returns the problems.
"""
from __future__ import annotations

import base64
import hashlib
import html
import io
import json
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

from airpose_lib.paths import PLACEHOLDERS, figures_root, portable, profile_name, runs_root

from .runner import CATALOG_PATH, REPO_ROOT, CatalogEntry, load_catalog

__all__ = ["FIGURES_README", "DEFAULT_MAX_IMAGE_PX", "REFERENCE_MAX_IMAGE_PX", "REFERENCE_MAX_BYTES", "ReportResult", "figure_captions", "execution_errors",
           "shrink_image", "build_report"]

#: The captions of the catalogue's figures (a Markdown table: figure, notebook, paper, how to read it).
FIGURES_README = REPO_ROOT / "figures" / "README.md"
#: The longer side of every image in a report, in pixels.
DEFAULT_MAX_IMAGE_PX = 1200
#: The committed report of a reference run (``results/<profile>/report/``, ``--write-reference``):
#: smaller images, and a cap on the folder's size so that the repository stays light.
REFERENCE_MAX_IMAGE_PX = 1000
REFERENCE_MAX_BYTES = 15_000_000
_INDEX_TEMPLATE = Path(__file__).resolve().parent / "report_index.html.j2"
# A JPEG replaces a PNG only when it is this much smaller: renders and photographs shrink, while
# line plots (few colours, sharp edges) stay PNG and stay sharp.
_JPEG_GAIN = 0.5


@dataclass
class ReportResult:
    """What :func:`build_report` wrote.

    Attributes:
        out_dir: the report folder; ``index.html`` is its first page.
        pages: notebook name -> its page's file name, in catalogue order.
        problems: one line per problem (a missing notebook, an error output, a missing figure).
        total_bytes: the size of the folder.
    """

    out_dir: Path
    pages: dict[str, str] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    total_bytes: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems

    def summary(self) -> str:
        return (f"report: {self.out_dir / 'index.html'} ({len(self.pages)} notebook pages, "
                f"{self.total_bytes / 1e6:.1f} MB)")


# -- reading ----------------------------------------------------------------------------------------
def _expand_braces(name: str) -> list[str]:
    """``table1_ablation.{csv,md}`` -> ``[table1_ablation.csv, table1_ablation.md]``."""
    m = re.fullmatch(r"(.*)\{([^}]*)\}(.*)", name)
    return [f"{m[1]}{part}{m[3]}" for part in m[2].split(",")] if m else [name]


def figure_captions(readme: Path = FIGURES_README) -> dict[str, dict[str, str]]:
    """Each figure file of the README's table -> ``{"paper": ..., "how": ...}`` (Markdown text).

    A row may name several files (``a.png``, ``b.png``) or a brace group (``t.{csv,md}``); each gets
    the row's caption.
    """
    captions = {}
    for line in Path(readme).read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 4 or not cells[0].startswith("`"):
            continue
        for name in re.findall(r"`([^`]+)`", cells[0]):
            for file in _expand_braces(name):
                captions[file] = {"paper": cells[2], "how": " | ".join(cells[3:])}
    return captions


def execution_errors(nb) -> list[str]:
    """One line per error output of an executed notebook: ``cell N: Name: message``."""
    return [f"cell {i}: {out.get('ename', 'error')}: {out.get('evalue', '')}"
            for i, cell in enumerate(nb.cells) if cell.cell_type == "code"
            for out in cell.get("outputs", []) if out.get("output_type") == "error"]


# -- images -----------------------------------------------------------------------------------------
def shrink_image(data: bytes, max_px: int) -> tuple[bytes, str]:
    """An image downscaled to at most ``max_px`` on its longer side, re-encoded.

    Returns:
        the bytes and their MIME type: PNG, or JPEG when the image is opaque and the JPEG is under
        half the PNG's size (a render or photograph).
    """
    from PIL import Image  # Pillow comes with matplotlib; imported where the report needs it

    img = Image.open(io.BytesIO(data))
    img.load()
    if max(img.size) > max_px:
        img.thumbnail((max_px, max_px), Image.LANCZOS)
    png = io.BytesIO()
    img.save(png, format="PNG", optimize=True)
    opaque = img.mode in ("RGB", "L") or (img.mode == "RGBA" and img.getchannel("A").getextrema()[0] == 255)
    if opaque:
        jpeg = io.BytesIO()
        img.convert("RGB").save(jpeg, format="JPEG", quality=88, optimize=True)
        if jpeg.tell() < _JPEG_GAIN * png.tell():
            return jpeg.getvalue(), "image/jpeg"
    return png.getvalue(), "image/png"


def _shrink_outputs(nb, max_px: int) -> None:
    """Downscale every PNG/JPEG output of the notebook in place."""
    for cell in nb.cells:
        for out in cell.get("outputs", []):
            data = out.get("data") or {}
            for mime in ("image/png", "image/jpeg"):
                if mime in data:
                    raw, new_mime = shrink_image(base64.b64decode(data.pop(mime)), max_px)
                    data[new_mime] = base64.b64encode(raw).decode("ascii")
                    break


# -- writing ----------------------------------------------------------------------------------------
def _page_name(entry: CatalogEntry) -> str:
    return f"{entry.name}.html"


def _nav_cell(catalog: list[CatalogEntry], i: int):
    """A Markdown cell with links to the index and the neighbouring pages (added to the page only)."""
    links = ["[index](index.html)"]
    if i > 0:
        links.insert(0, f"[&larr; {catalog[i - 1].name}]({_page_name(catalog[i - 1])})")
    if i + 1 < len(catalog):
        links.append(f"[{catalog[i + 1].name} &rarr;]({_page_name(catalog[i + 1])})")
    return nbformat.v4.new_markdown_cell(" · ".join(links) + f"\n\n*Reproduces:* {catalog[i].reproduces}")


def _notebook_page(nb, catalog: list[CatalogEntry], i: int, max_px: int, out_dir: Path) -> str:
    """The notebook as a page of the report (nbconvert's lab template), with navigation links;
    its paths (the parameters cell's ``output_dir``, a printed cache file) named
    :func:`~airpose_lib.paths.portable`, as the reference report is committed."""
    from nbconvert import HTMLExporter  # with jupyter; offline

    _shrink_outputs(nb, max_px)
    nav = _nav_cell(catalog, i)
    nb.cells = [nav, *nb.cells, nbformat.v4.new_markdown_cell(nav.source.split("\n")[0])]
    body, _ = HTMLExporter(template_name="lab").from_notebook_node(nb)
    return _portable_page(_shared_stylesheet(body, out_dir))


def _portable_page(page: str) -> str:
    """An HTML page with its paths named :func:`~airpose_lib.paths.portable` (a reference report
    is committed), the placeholders escaped: a bare ``<cache>`` is a tag the browser hides."""
    page = portable(page)
    for placeholder in PLACEHOLDERS:
        page = page.replace(placeholder, html.escape(placeholder))
    return page


def _shared_stylesheet(page: str, out_dir: Path) -> str:
    """Move the style sheets nbconvert inlines into each page's head (about 260 kB, the same on
    every page) into one file the pages link to."""
    head_end = page.index("</head>")
    head = page[:head_end]
    css = "\n".join(re.findall(r"<style[^>]*>(.*?)</style>", head, flags=re.S))
    if not css:
        return page
    name = f"notebook-{hashlib.sha256(css.encode()).hexdigest()[:8]}.css"
    (out_dir / name).write_text(css)
    head = re.sub(r"<style[^>]*>.*?</style>\s*", "", head, flags=re.S)
    return f'{head}<link rel="stylesheet" href="{name}">\n{page[head_end:]}'


def _read_json(path: Path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return {}


def _copy_figure(src: Path, dst_dir: Path, max_px: int) -> str:
    """Copy one figure into the report (images downscaled); returns its file name there."""
    if src.suffix.lower() != ".png":
        shutil.copyfile(src, dst_dir / src.name)
        return src.name
    raw, mime = shrink_image(src.read_bytes(), max_px)
    name = src.name if mime == "image/png" else src.with_suffix(".jpg").name
    (dst_dir / name).write_bytes(raw)
    return name


def _folder_bytes(folder: Path) -> int:
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file())


def build_report(profile: str, run_dir: str | Path | None = None, figures_dir: str | Path | None = None,
                 out_dir: str | Path | None = None, max_image_px: int = DEFAULT_MAX_IMAGE_PX,
                 catalog_path: str | Path | None = None, readme: str | Path | None = None,
                 max_bytes: int | None = None) -> ReportResult:
    """Write the HTML report of a profile's reproduction.

    Args:
        profile: the profile's name (``smoke``, ``cpu``, ``paper``).
        run_dir: the run folder of ``airpose reproduce`` (default ``<runs>/<profile>``).
        figures_dir: the collected figures (default ``figures/<profile>``).
        out_dir: where the report goes (default ``<run_dir>/report``); replaced as a whole.
        max_image_px: the longer side of every image in the report.
        catalog_path, readme: the catalogue and the captions (default :data:`CATALOG_PATH`,
            :data:`FIGURES_README`).
        max_bytes: a cap on the report's size (a larger report is a problem), or None.
    Returns:
        a :class:`ReportResult`; ``.problems`` lists every missing notebook, error output and
        missing figure (the report is written all the same).
    Raises:
        FileNotFoundError: ``run_dir`` has no executed notebooks at all (nothing to report).
        FileExistsError: ``out_dir`` holds files but no earlier report (it is never emptied then).
    """
    from jinja2 import Environment  # with nbconvert
    from nbconvert.filters import markdown2html  # the README's captions are Markdown

    run_dir = Path(run_dir) if run_dir is not None else runs_root() / profile_name(profile)
    figures_dir = Path(figures_dir) if figures_dir is not None else figures_root() / profile_name(profile)
    out_dir = Path(out_dir) if out_dir is not None else run_dir / "report"
    notebooks_dir = run_dir / "notebooks"
    if not any(notebooks_dir.glob("*.ipynb")):
        raise FileNotFoundError(f"{notebooks_dir}: no executed notebooks; run `airpose reproduce --profile "
                                f"{profile}` first (or pass the run folder)")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / "index.html").is_file():
        # the folder is replaced as a whole: only ever an earlier report
        raise FileExistsError(f"{out_dir} is not empty and holds no report (index.html); choose a new or "
                              f"empty folder for the report")
    readme = Path(readme) if readme is not None else FIGURES_README
    catalog = load_catalog(Path(catalog_path) if catalog_path is not None else CATALOG_PATH)
    captions = figure_captions(readme)
    run = _read_json(run_dir / "report.json")
    wall = {r["name"]: r for r in run.get("results", [])}
    result = ReportResult(out_dir=out_dir)

    tmp = out_dir.with_name(out_dir.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    (tmp / "figures").mkdir(parents=True)
    rows = []
    for i, entry in enumerate(catalog):
        path = notebooks_dir / Path(entry.file).name
        # report.json lists the notebooks of the last `reproduce` call only (--only): the others'
        # executed files, if any, come from an earlier call
        row = {"entry": entry, "page": None, "status": wall.get(entry.name, {}).get("status", "earlier run"),
               "wall_s": wall.get(entry.name, {}).get("wall_s"), "errors": [], "figures": []}
        if path.is_file():
            nb = nbformat.read(path, as_version=4)
            row["errors"] = execution_errors(nb)
            result.problems += [f"{entry.name}: execution error in {c}" for c in row["errors"]]
            (tmp / _page_name(entry)).write_text(_notebook_page(nb, catalog, i, max_image_px, tmp))
            row["page"] = result.pages[entry.name] = _page_name(entry)
        else:
            result.problems.append(f"{entry.name}: no executed notebook {path}")
        for fig in entry.figures:
            src, caption = figures_dir / fig, captions.get(fig)
            if not src.is_file():
                result.problems.append(f"{entry.name}: figure {fig} missing from {figures_dir}")
                continue
            if caption is None:
                result.problems.append(f"{entry.name}: figure {fig} has no caption in {readme}")
            row["figures"].append({"name": fig, "file": _copy_figure(src, tmp / "figures", max_image_px),
                                   "image": src.suffix.lower() == ".png", "caption": caption or {}})
        rows.append(row)

    bundle = _read_json(run_dir / "02_ablation_table" / "results" / "provenance.json")
    index = Environment(autoescape=True).from_string(_INDEX_TEMPLATE.read_text()).render(
        profile=profile, run=run, rows=rows, bundle=bundle, problems=result.problems,
        md=markdown2html)
    (tmp / "index.html").write_text(_portable_page(index))
    shutil.rmtree(out_dir, ignore_errors=True)
    tmp.rename(out_dir)
    result.total_bytes = _folder_bytes(out_dir)
    if max_bytes is not None and result.total_bytes > max_bytes:
        result.problems.append(f"the report is {result.total_bytes / 1e6:.1f} MB, over the cap of "
                               f"{max_bytes / 1e6:.1f} MB: build it with smaller images (max_image_px)")
    return result

