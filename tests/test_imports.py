"""Every module of ``plls_bench`` and ``baselines`` imports on its own, and their imports run only
down the declared layers (:data:`LAYERS`) and form no cycle.

Every import statement counts, wherever it stands: at module level, inside a function (a deferred
import hides a cycle until the function runs), under ``if TYPE_CHECKING:`` (a type-only circle is
still a circle). Importing ``a.b.c`` from outside ``a.b`` also runs ``a/b/__init__.py``, so it
counts as importing that package too.
"""
from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

from tests.conftest import REPO_ROOT

PACKAGES = ("plls_bench", "baselines")
Graph = dict[str, dict[str, int]]  # module -> {imported project module: line of its first import}

# Bottom up. A module belongs to the layer of its longest entry (the module or a package above it;
# a bare root package is only itself) and imports only from its own layer and those below.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundation", ("plls_bench", "plls_bench.files", "plls_bench.hashing", "plls_bench.seeding", "plls_bench.progress",
                    "plls_bench.signals", "plls_bench.heap", "plls_bench.metrics", "plls_bench.evaluate")),
    ("config", ("plls_bench.config",)),
    ("run dirs", ("plls_bench.devices", "plls_bench.provenance", "plls_bench.runs", "plls_bench.artifacts",
                  "plls_bench.composition", "plls_bench.sweeps", "plls_bench.overrides", "plls_bench.records",
                  "plls_bench.manifest")),
    ("tasks", ("plls_bench.envs", "plls_bench.data", "plls_bench.trunks")),
    ("representations", ("plls_bench.repr", "plls_bench.latent")),
    ("baselines", ("baselines", "baselines.dbc")),
    ("learners", ("plls_bench.train",)),
    ("analyses", ("plls_bench.analysis",)),
    ("registry", ("plls_bench.runner_specs",)),
    ("commands", ("plls_bench.runner", "plls_bench.__main__", "plls_bench.plan", "plls_bench.rates",
                  "plls_bench.reproduce", "plls_bench.launch",
                  "plls_bench.resolve", "plls_bench.film", "plls_bench.records.export",
                  "plls_bench.records.__main__")),
    ("report", ("plls_bench.report",)),
)


def module_files() -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the packages."""
    found = {}
    for package in PACKAGES:
        for path in sorted((REPO_ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(REPO_ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _targets(node: ast.Import | ast.ImportFrom, module: str, is_package: bool, known: set[str]) -> set[str]:
    """The project modules an import statement of ``module`` loads: those it names, and the
    packages above them whose ``__init__`` runs first (unless ``module`` is inside, so already
    being imported)."""
    if isinstance(node, ast.Import):
        named = {alias.name for alias in node.names}
    else:
        base = node.module or ""
        if node.level:  # relative: from the module's package, up level - 1 more
            anchor = module.split(".") if is_package else module.split(".")[:-1]
            anchor = anchor[:len(anchor) - (node.level - 1)]
            base = ".".join([*anchor, *([base] if base else [])])
        submodules = {f"{base}.{alias.name}" for alias in node.names}
        named = submodules if submodules <= known else (submodules & known) | {base}
    named &= known
    packages = {".".join(name.split(".")[:i]) for name in named for i in range(1, name.count(".") + 1)}
    return (named | {p for p in packages & known if not module.startswith(p + ".")}) - {module}


def import_graph(files: dict[str, Path] | None = None) -> Graph:
    """Module -> the project modules any of its import statements loads, anywhere in the file."""
    files = module_files() if files is None else files
    known = set(files)
    graph: Graph = {}
    for module, path in files.items():
        edges: dict[str, int] = {}
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                for target in _targets(node, module, path.name == "__init__.py", known):
                    edges[target] = min(edges.get(target, node.lineno), node.lineno)
        graph[module] = dict(sorted(edges.items()))
    return graph


def find_cycle(graph: dict[str, list[str]] | Graph) -> list[str] | None:
    """One cycle of ``graph`` as ``[a, b, ..., a]``, or None when it is acyclic."""
    state: dict[str, int] = {}  # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in graph.get(node, []):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


def layer_of(module: str, layers: tuple[tuple[str, tuple[str, ...]], ...] = LAYERS) -> int | None:
    """Index in ``layers`` of the module's longest entry; None when no entry holds it."""
    best: tuple[int, int] | None = None  # (entry length, layer index)
    for index, (_, entries) in enumerate(layers):
        for entry in entries:
            holds = module == entry or (module.startswith(entry + ".") and entry not in PACKAGES)
            if holds and (best is None or len(entry) > best[0]):
                best = (len(entry), index)
    return None if best is None else best[1]


def upward_imports(graph: Graph, layers: tuple[tuple[str, tuple[str, ...]], ...] = LAYERS) -> list[str]:
    """Every import that runs back up the layers, as a readable line."""
    found = []
    for module, edges in sorted(graph.items()):
        for target, line in edges.items():
            low, high = layer_of(module, layers), layer_of(target, layers)
            if low is not None and high is not None and high > low:
                found.append(f"{module} (line {line}, layer {layers[low][0]}) imports {target} "
                             f"(layer {layers[high][0]})")
    return found


def test_the_package_imports_run_only_down_the_layers_and_form_no_cycle() -> None:
    graph = import_graph()
    assert len(graph) > 50 and "plls_bench.repr.store" in graph["plls_bench.latent"]
    assert "plls_bench.train.ppo" in graph["plls_bench.runner_specs"], "imports inside functions are read"
    unplaced = sorted(module for module in graph if layer_of(module) is None)
    assert not unplaced, f"modules in no layer of LAYERS: {unplaced}"
    upward = upward_imports(graph)
    assert not upward, "imports that run back up the layers:\n" + "\n".join(upward)
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_the_checks_find_a_cycle_an_upward_import_and_a_deferred_one(tmp_path: Path) -> None:
    assert find_cycle({"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": ["b"], "b": [], "c": ["a", "b"]}) is None
    layers = (("low", ("p.low",)), ("high", ("p.high",)))
    (tmp_path / "p").mkdir()
    (tmp_path / "p" / "__init__.py").write_text("")
    (tmp_path / "p" / "high.py").write_text("from p.low import x\n")
    (tmp_path / "p" / "low.py").write_text("def f():\n    from p import high\n")  # deferred, back up
    graph = import_graph({name: tmp_path / "p" / f"{file}.py" for name, file in
                          (("p", "__init__"), ("p.high", "high"), ("p.low", "low"))})
    assert graph["p.low"] == {"p.high": 2} and find_cycle(graph) == ["p.high", "p.low", "p.high"]
    assert upward_imports(graph, layers) == ["p.low (line 2, layer low) imports p.high (layer high)"]


def test_the_documented_layout_shows_the_layers_bottom_up() -> None:
    page = (REPO_ROOT / "docs" / "architecture.md").read_text()
    block = page.split("## Layout", 1)[1].split("```", 2)[1]
    shown = re.findall(r"^  (\S(?:\S| (?! ))*)  ", block, flags=re.MULTILINE)
    assert shown == [name for name, _ in LAYERS]


def test_every_module_imports_on_its_own_in_a_fresh_process() -> None:
    modules = sorted(module_files())
    done = subprocess.run([sys.executable, "-m", "tests.import_each", *modules], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    failures = json.loads(done.stdout.strip().splitlines()[-1])
    assert not failures, "\n\n".join(f"{m}:\n{tb}" for m, tb in failures.items())
