"""The package layers of ``airpose_lib``: no import cycles between packages, and every package
imports only the packages its row of :data:`ALLOWED` names (``airpose_lib/LAYERS.md`` explains
the table; it follows the design sketch, with the changes the code asked for).

Imports are read from the source with ``ast`` (module level and inside functions alike, so a lazy
import counts as a dependency too); nothing is imported.
"""
from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "airpose_lib"
KIT = "airpose_lib"

# Top-level helper modules (standard library only, no package of the kit): every package may use them.
BASE = {"_lazy", "atomic", "config_fields", "devices", "errors", "folder_lock", "hashing", "paths", "process_guard", "progress",
        "safe_pickle"}

# package -> the packages it may import (BASE aside). The design sketch's table with the changes
# the code asked for; airpose_lib/LAYERS.md gives the reasons. Keep the two in step.
ALLOWED: dict[str, set[str]] = {
    "geometry": set(),
    "profiles": set(),
    "assets": set(),
    "engine": set(),
    "zoo": {"engine"},
    "body": {"geometry", "assets"},
    "losses": {"geometry", "body"},
    "model": {"geometry", "body"},
    "viz": {"geometry", "body"},
    "data": {"geometry", "body", "viz"},
    "eval": {"geometry", "body", "model"},
    "prior": {"geometry", "body", "data", "engine"},
    "fitting": {"geometry", "body", "prior", "losses"},
    "train": {"geometry", "body", "assets", "data", "model", "losses", "eval", "engine"},
    "runtime": {"geometry", "body", "data", "model"},
    "finetune": {"geometry", "body", "data", "model", "losses", "prior", "train", "engine"},
    "experiments": {"geometry", "body", "assets", "data", "model", "losses", "eval", "viz", "prior", "fitting",
                    "train", "finetune", "runtime", "engine", "zoo"},
    # the entry: the runner, the notebooks' set-up, and the profile typed once (reproduce.configs)
    "reproduce": {"assets", "viz", "profiles", "data", "train", "prior", "finetune", "fitting", "experiments"},
    "cli": {"geometry", "profiles", "body", "assets", "data", "model", "losses", "eval", "viz", "prior", "fitting", "train",
            "finetune", "runtime", "experiments", "reproduce", "engine", "zoo"},
}

# data's wings, bottom first: a module of data imports data's modules of its own wing or of a wing
# before it, never one after it (LAYERS.md gives the reasons).
DATA_WINGS = ("network_input", "still", "sequences", "video", "official")

# The most kit modules one module of experiments imports: a module there is one stage of an
# experiment, and one that needs more does several jobs (split it by stage).
EXPERIMENT_MAX_IMPORTS = 13

# Circles that are real recursion, each broken by a commented import inside a function.
ACCEPTED_MODULE_CYCLES: dict[frozenset[str], str] = {}


def _package_of(module: str) -> str | None:
    """``airpose_lib.data.still.render`` -> ``data``; a BASE module or the kit's root -> None."""
    parts = module.split(".")
    if parts[0] != KIT or len(parts) < 2 or parts[1] in BASE:
        return None
    is_package = (ROOT / parts[1] / "__init__.py").is_file() or (ROOT / f"{parts[1]}.py").is_file()
    return parts[1] if is_package and parts[1] != "__main__" else None  # else a name of the root


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """The kit modules ``path`` imports, anywhere in the file (absolute names)."""
    name = _module_name(path)
    is_pkg = path.name == "__init__.py"
    tree = ast.parse(path.read_text(), filename=str(path))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[:len(base) - node.level + (1 if is_pkg else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            found.update(f"{target}.{a.name}" for a in node.names)  # `from pkg import module`
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", None)) \
                == "import_module" and node.args and isinstance(node.args[0], ast.Constant):
            found.add(str(node.args[0].value))  # importlib.import_module("airpose_lib.body")
    return {m for m in found if m == KIT or m.startswith(KIT + ".")}


def package_graph() -> dict[str, dict[str, list[str]]]:
    """package -> imported package -> the imports (``file -> target``) that make the edge. A BASE
    helper that imports a package shows up as a package of its own (and has no row)."""
    graph: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for path in sorted(ROOT.rglob("*.py")):
        if path.parent == ROOT:  # the kit's __init__/__main__ (above everything), or a helper
            src = path.stem if path.stem in BASE else None
        else:
            src = _package_of(_module_name(path))
        for target in _imports(path):
            dst = _package_of(target)
            if src is None or dst is None or dst == src:
                continue
            graph[src][dst].append(f"{path.relative_to(ROOT.parent)} -> {target}")
    return graph


def _cycles(graph) -> list[list[str]]:
    """Strongly connected components of more than one package (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def test_every_package_has_a_row():
    packages = {p.name for p in ROOT.iterdir() if (p / "__init__.py").is_file()}
    assert packages == set(ALLOWED), "add the new package to ALLOWED (and LAYERS.md), or remove the old row"
    helpers = {p.stem for p in ROOT.glob("*.py")} - {"__init__", "__main__"}
    assert helpers == BASE, "a top-level module is a helper every package may use: add it to BASE (and LAYERS.md)"


def test_no_cycles_between_packages():
    graph = package_graph()
    cycles = _cycles(graph)
    detail = [f"{' <-> '.join(c)}: " + "; ".join(e for a in c for b in c if b in graph.get(a, {})
                                                   for e in graph[a][b][:2]) for c in cycles]
    assert not cycles, "import cycles between packages:\n" + "\n".join(detail)


def test_dependencies_follow_the_layers():
    graph = package_graph()
    bad = [f"{src} -> {dst} ({'; '.join(edges[:3])})" for src, deps in sorted(graph.items())
           for dst, edges in sorted(deps.items()) if dst not in ALLOWED.get(src, set())]
    assert not bad, "imports against the layers (fix the import, or argue the table in LAYERS.md):\n" + \
        "\n".join(bad)


def _module_cycles() -> list[list[str]]:
    graph: dict[str, dict[str, list]] = defaultdict(dict)
    modules = {_module_name(p): p for p in ROOT.rglob("*.py")}
    for name, path in modules.items():
        for target in _imports(path):
            while target not in modules and "." in target:  # `from pkg import name`: the module
                target = target.rsplit(".", 1)[0]
            if target != name and target in modules and not _is_ancestor(target, name):
                graph[name][target] = []
    return _cycles(graph)


def _is_ancestor(package: str, module: str) -> bool:
    """Importing ``a.b.c`` runs ``a/b/__init__``: a module naturally 'imports' its parents."""
    return module.startswith(package + ".")


def test_no_cycles_between_modules():
    cycles = [c for c in _module_cycles() if frozenset(c) not in ACCEPTED_MODULE_CYCLES]
    assert not cycles, "import cycles between modules:\n" + "\n".join(" <-> ".join(c) for c in cycles)


@pytest.mark.parametrize("module", ["airpose_lib.cli", "airpose_lib.runtime.source"])
def test_graph_sees_lazy_imports(module):
    """The reader finds imports inside functions too (the check would be blind without them)."""
    path = ROOT.parent / (module.replace(".", "/") + ".py")
    if not path.exists():
        path = path.with_suffix("") / "__init__.py"
    assert _imports(path)


def _data_wing(module: str) -> int | None:
    """``airpose_lib.data.still.scene`` -> the index of ``still`` in :data:`DATA_WINGS`; None
    outside data's wings (``airpose_lib.data`` itself, or another package)."""
    parts = module.split(".")
    if parts[:2] != [KIT, "data"] or len(parts) < 3:
        return None
    return DATA_WINGS.index(parts[2]) if parts[2] in DATA_WINGS else None


def climbing_data_imports() -> list[str]:
    """``file -> target`` for each import of a data module from a wing above the importer's."""
    bad = []
    for path in sorted((ROOT / "data").rglob("*.py")):
        src = _data_wing(_module_name(path))
        for target in sorted(_imports(path)):
            dst = _data_wing(target)
            if src is not None and dst is not None and dst > src:
                bad.append(f"{path.relative_to(ROOT.parent)} -> {target}")
    return bad


def test_every_data_wing_is_ordered():
    wings = {p.stem for p in (ROOT / "data").iterdir() if p.stem != "__init__" and
             ((p / "__init__.py").is_file() or p.suffix == ".py")}
    assert wings == set(DATA_WINGS), "add the new wing of data to DATA_WINGS (and LAYERS.md)"


def test_data_wings_import_downwards():
    bad = climbing_data_imports()
    assert not bad, f"imports that climb data's wings ({' < '.join(DATA_WINGS)}):\n" + "\n".join(bad)


def kit_modules_imported(path: Path) -> set[str]:
    """The kit modules ``path`` imports, each once: ``from pkg import name`` counts ``pkg.name``
    when that is a module, else ``pkg`` (helpers count too)."""
    modules = {_module_name(p) for p in ROOT.rglob("*.py")}
    name, is_pkg = _module_name(path), path.name == "__init__.py"
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = name.split(".")[:len(name.split(".")) - node.level + (1 if is_pkg else 0)] if node.level else []
            target = ".".join(base + ([node.module] if node.module else []))
            found.update(f"{target}.{a.name}" if f"{target}.{a.name}" in modules else target for a in node.names)
    return {m for m in found if m.startswith(KIT + ".")} - {name}


def test_experiment_modules_import_few_of_the_kit():
    heavy = {_module_name(p): len(kit_modules_imported(p)) for p in sorted((ROOT / "experiments").rglob("*.py"))}
    heavy = {m: n for m, n in heavy.items() if n > EXPERIMENT_MAX_IMPORTS}
    assert not heavy, f"modules of experiments importing more than {EXPERIMENT_MAX_IMPORTS} of the kit's (split " \
        f"them by stage): {heavy}"


# -- configuration typed once, at the entry -------------------------------------------------------
# The layers that read a profile: the profile files' own package, the command line and the runner
# with the notebooks' set-up (reproduce.configs.kit_configs turns every section into its config).
ENTRY = {"profiles", "cli", "reproduce"}
# The functions of airpose_lib.profiles that read a profile (a file, a section, a config of one).
SECTION_READERS = {"loaded", "read_profile", "profile_path", "profile_section", "section_where", "section_config"}


def _calls_outside_the_entry(names: set[str]) -> list[str]:
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if rel.parts[0] in ENTRY:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
                if name in names:
                    found.append(f"{rel}:{node.lineno} {name}")
    return found


def test_no_section_is_read_below_the_entry():
    """The entry types the profile once; below it, code takes the config it needs: no call of a
    profile reader outside profiles/, cli/ and reproduce/, and no package there imports profiles."""
    assert not _calls_outside_the_entry(SECTION_READERS)
    importers = {src for src, edges in package_graph().items() for dst in edges if dst == "profiles"}
    assert importers <= ENTRY, f"packages below the entry that import profiles: {sorted(importers - ENTRY)}"
