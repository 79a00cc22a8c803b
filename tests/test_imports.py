"""Every module of ``plls_bench`` and ``baselines`` imports on its own, and their imports run only
down the layers (:data:`LAYERS`, declared by folder) and form no cycle.

Every import statement counts, wherever it stands: at module level, inside a function (a deferred
import hides a cycle until the function runs), under ``if TYPE_CHECKING:`` (a type-only circle is
still a circle). Importing ``a.b.c`` from outside ``a.b`` also runs ``a/b/__init__.py``, so it
counts as importing that package too. ``baselines`` is the bottom layer: the suite's
learners import it, and it imports nothing of the suite (the suite hands it its conv stack).
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
Layers = tuple[tuple[str, tuple[str, ...]], ...]

# Bottom up, by folder: ``dir/`` holds the modules in dir and below it, ``dir/*.py`` the modules
# directly in dir. A module belongs to the layer of its longest folder; it imports only from its
# own layer and those below. Each layer folder's __init__ docstring says the same.
LAYERS: Layers = (
    ('baselines', ('baselines/',)),
    ('core', ('plls_bench/core/', 'plls_bench/__init__.py')),
    ('config', ('plls_bench/config/',)),
    ('run dirs', ('plls_bench/rundirs/',)),
    ('tasks', ('plls_bench/envs/', 'plls_bench/data/')),
    ('representations', ('plls_bench/repr/',)),
    ('learners', ('plls_bench/train/',)),
    ('analyses', ('plls_bench/studies/', 'plls_bench/validation/')),
    ('pipeline', ('plls_bench/pipeline/',)),
    ('report evidence', ('plls_bench/report/evidence/',)),
    ('report figures', ('plls_bench/report/figures/',)),
    ('report tables', ('plls_bench/report/tables/',)),
    ('report claims', ('plls_bench/report/claims/',)),
    ('report', ('plls_bench/report/*.py',)),
    ('entry points', ('plls_bench/*.py', 'plls_bench/film/')),
)


def module_files(root: Path = REPO_ROOT) -> dict[str, Path]:
    """Dotted module name -> source file, for every module of the packages."""
    found = {}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
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


def layer_of(file: str, layers: Layers = LAYERS) -> int | None:
    """Index in ``layers`` of the longest entry holding ``file`` (a path relative to the root):
    ``dir/`` its folder or one above, ``dir/*.py`` its folder, or the file itself; None when none does."""
    folder = file.rsplit("/", 1)[0] + "/"
    best: tuple[int, int] | None = None  # (folder length, layer index)
    for index, (_, entries) in enumerate(layers):
        for entry in entries:
            if entry.endswith("*.py"):
                holds = folder == entry.removesuffix("*.py")
            else:
                holds = folder.startswith(entry) if entry.endswith("/") else file == entry
            if holds and (best is None or len(entry) > best[0]):
                best = (len(entry), index)
    return None if best is None else best[1]


def upward_imports(graph: Graph, files: dict[str, Path], root: Path = REPO_ROOT,
                   layers: Layers = LAYERS) -> list[str]:
    """Every import that runs back up the layers, as a readable line."""
    layer = {m: layer_of(p.relative_to(root).as_posix(), layers) for m, p in files.items()}
    found = []
    for module, edges in sorted(graph.items()):
        for target, line in edges.items():
            low, high = layer[module], layer[target]
            if low is not None and high is not None and high > low:
                found.append(f"{module} (line {line}, layer {layers[low][0]}) imports {target} "
                             f"(layer {layers[high][0]})")
    return found


def test_the_package_imports_run_only_down_the_layers_and_form_no_cycle() -> None:
    files = module_files()
    graph = import_graph(files)
    assert len(graph) > 50 and "plls_bench.repr.store" in graph["plls_bench.repr.latent_wrappers"]
    assert "plls_bench.train.ppo" in graph["plls_bench.pipeline.runner_registry"], "imports inside functions are read"
    unplaced = sorted(m for m, p in files.items() if layer_of(p.relative_to(REPO_ROOT).as_posix()) is None)
    assert not unplaced, f"modules in no folder of LAYERS: {unplaced}"
    upward = upward_imports(graph, files)
    assert not upward, "imports that run back up the layers:\n" + "\n".join(upward)
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_every_layer_folder_says_its_layer_in_its_docstring() -> None:
    named = {e for _, entries in LAYERS for e in entries if e.endswith(".py") and not e.endswith("*.py")}
    wrong = []
    for name, entries in LAYERS:
        for entry in entries:
            init = entry.removesuffix("*.py").rstrip("/") + "/__init__.py"
            if not entry.endswith(("/", "*.py")) or init in named:
                continue  # a file entry, or a folder whose __init__ is a layer of its own
            path = REPO_ROOT / init
            doc = " ".join((ast.get_docstring(ast.parse(path.read_text())) or "").split()) if path.is_file() else ""
            if f"Layer ``{name}``" not in doc:
                wrong.append(f"{init} does not say Layer ``{name}``")
    assert not wrong, "\n".join(wrong)


def test_the_checks_find_a_cycle_an_upward_import_and_a_deferred_one(tmp_path: Path) -> None:
    assert find_cycle({"a": ["b"], "b": ["c"], "c": ["a"], "d": ["a"]}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": ["b"], "b": [], "c": ["a", "b"]}) is None
    layers = (("low", ("p/low/",)), ("high", ("p/*.py",)))
    (tmp_path / "p" / "low").mkdir(parents=True)
    for name, text in (("p/__init__.py", ""), ("p/high.py", "from p.low.x import f\n"),
                       ("p/low/__init__.py", ""), ("p/low/x.py", "def f():\n    from p import high\n")):
        (tmp_path / name).write_text(text)  # p/low/x.py: deferred, back up
    files = {"p": tmp_path / "p/__init__.py", "p.high": tmp_path / "p/high.py",
             "p.low": tmp_path / "p/low/__init__.py", "p.low.x": tmp_path / "p/low/x.py"}
    graph = import_graph(files)
    assert graph["p.low.x"] == {"p.high": 2} and find_cycle(graph) == ["p.high", "p.low.x", "p.high"]
    assert upward_imports(graph, files, tmp_path, layers) == [
        "p.low.x (line 2, layer low) imports p.high (layer high)"]
    assert layer_of("p/low/deeper/y.py", layers) == 0 and layer_of("p/other/z.py", layers) is None


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
