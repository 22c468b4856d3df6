"""The package is layered and has no import cycles, deferred imports (inside functions) included.

Every module of ``shspec`` belongs to one unit (a subpackage or a top-level module) and every unit to one layer of
:data:`LAYERS`, listed from the bottom up.  A module may import modules of its own unit and of units in lower layers;
units of the same layer are peers and do not import each other (the Galerkin solver and the mesh path are both
discretizations behind the :mod:`shspec.spectral_model` seam).  Importing ``a.b.c`` executes the packages ``a`` and ``a.b``
too, so those count as imported, except the importing module's own parents (already executing).
"""

import ast
from pathlib import Path

import pytest

import shspec

#: The one declaration of the layer order, bottom first.
LAYERS = (
    ("_version", "errors"),
    ("core",),
    ("report", "spectral_model", "sphere", "spectrum_file"),
    ("gaunt",),
    ("galerkin", "mesh"),
    ("embed",),
    ("spectral", "inverse"),
    ("fitting",),
    ("pipeline", ""),  # "" is the root package shspec/__init__.py: the public API over everything below
    ("experiments",),
    ("cli",),
    ("__main__",),
)

ROOT = Path(shspec.__file__).parent


def _modules(root: Path) -> dict:
    """Dotted module name -> (path, is_package) for every module under ``root``."""
    mods = {}
    for path in root.rglob("*.py"):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        package = parts[-1] == "__init__"
        if package:
            parts = parts[:-1]
        mods[".".join(parts)] = (path, package)
    return mods


def _imports(name: str, path: Path, package: bool, mods: dict) -> set:
    """Every shspec module that ``name`` imports anywhere in its body, with the parent packages that runs."""
    here = name.split(".") if package else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom):
            base = ".".join(here[:len(here) - node.level + 1] + [node.module] if node.module else
                            here[:len(here) - node.level + 1]) if node.level else node.module or ""
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in mods else base for alias in node.names]
        elif isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            continue
        for target in targets:
            while target and target not in mods:
                target = target.rpartition(".")[0]
            parts = target.split(".")
            for i in range(1, len(parts) + 1):
                found.add(".".join(parts[:i]))
    own_parents = {".".join(name.split(".")[:i]) for i in range(1, name.count(".") + 1)}
    return {m for m in found if m in mods and m != name and m not in own_parents}


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _layer_of() -> dict:
    return {unit: i for i, layer in enumerate(LAYERS) for unit in layer}


def import_graph(root: Path = ROOT) -> dict:
    mods = _modules(root)
    return {name: _imports(name, path, package, mods) for name, (path, package) in mods.items()}


def cycles(graph: dict) -> list:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
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
    return out


def layer_violations(graph: dict) -> list:
    layer = _layer_of()
    bad = []
    for module, targets in graph.items():
        a = _unit(module)
        for target in targets:
            b = _unit(target)
            if a != b and layer[b] >= layer[a]:
                bad.append(f"{module} imports {target} ({'a peer' if layer[b] == layer[a] else 'a higher layer'})")
    return sorted(bad)


def test_every_unit_has_a_layer():
    units = {_unit(m) for m in import_graph()}
    assert units - set(_layer_of()) == set()


def test_no_import_cycles():
    assert cycles(import_graph()) == []


def test_no_upward_or_sideways_imports():
    assert layer_violations(import_graph()) == []


#: Units that may not import others although these are in lower layers: the inverse solver sees a discretization
#: only through the :mod:`shspec.spectral_model` seam and a target only through :class:`shspec.inverse.Target`, so
#: the Galerkin solver, the mesh path and what is built on them stay out of it.
SEAMS = {"inverse": ("galerkin", "mesh", "embed", "gaunt")}


def seam_violations(graph: dict) -> list:
    """``"a imports b (across the seam)"`` for every import of a unit kept out by :data:`SEAMS`."""
    return sorted(f"{name} imports {imp} (across the seam)" for name, imports in graph.items()
                  for imp in imports if _unit(imp) in SEAMS.get(_unit(name), ()))


def test_the_inverse_solver_imports_no_discretization():
    assert seam_violations(import_graph()) == []


def test_the_seam_check_sees_a_crossing(tmp_path):
    pkg = tmp_path / "shspec"
    (pkg / "galerkin").mkdir(parents=True)
    (pkg / "inverse").mkdir()
    for init in (pkg, pkg / "galerkin", pkg / "inverse"):
        (init / "__init__.py").write_text("")
    (pkg / "galerkin" / "model.py").write_text("x = 1\n")
    (pkg / "inverse" / "plan.py").write_text("def f():\n    from ..galerkin.model import x  # deferred\n")
    assert seam_violations(import_graph(pkg)) == [
        "shspec.inverse.plan imports shspec.galerkin (across the seam)",
        "shspec.inverse.plan imports shspec.galerkin.model (across the seam)"]


def test_the_checks_see_a_cycle_and_an_upward_import(tmp_path):
    # a deferred import closing a cycle and a lower layer importing a higher one, as the old tree had them
    pkg = tmp_path / "shspec"
    (pkg / "galerkin").mkdir(parents=True)
    (pkg / "inverse").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "galerkin" / "__init__.py").write_text("")
    (pkg / "inverse" / "__init__.py").write_text("")
    (pkg / "galerkin" / "solver.py").write_text("def f():\n    from .planning import g  # deferred\n")
    (pkg / "galerkin" / "planning.py").write_text("from .solver import f\nfrom ..inverse.identifiability import x\n")
    (pkg / "inverse" / "identifiability.py").write_text("x = 1\n")
    graph = import_graph(pkg)
    assert cycles(graph) == [["shspec.galerkin.planning", "shspec.galerkin.solver"]]
    assert layer_violations(graph) == [
        "shspec.galerkin.planning imports shspec.inverse (a higher layer)",
        "shspec.galerkin.planning imports shspec.inverse.identifiability (a higher layer)"]


@pytest.mark.parametrize("module", ["shspec.inverse.options", "shspec.galerkin.solver", "shspec.core.resources"])
def test_the_old_cycles_are_gone(module):
    graph = import_graph()
    assert not any(module in c for c in cycles(graph))


def test_the_package_root_holds_few_modules():
    """The folders show the layers: plumbing lives in ``shspec/core``, each domain in its package; at the root only
    the public API (``__init__``, ``__main__``, ``_version``) and at most six modules every layer shares."""
    root = sorted(p.stem for p in ROOT.glob("*.py") if p.stem not in ("__init__", "__main__", "_version"))
    assert len(root) <= 6, root
