"""The package's layers hold, read from the source with `ast` (imports inside functions included: a lazy
import is a dependency too). The layers are the list in `depthq`'s docstring, read from it here so
the two cannot drift; each name there is a folder (or a base module), so the folders show the layers:
every folder is in the list once, no folder imports a later one or a sibling unit, no folders import
each other round a loop, and no two modules import each other at import time."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import depthq

SRC = Path(depthq.__file__).parent


def _declared_layers() -> list[list[tuple[str, ...]]]:
    """The layers of `depthq`'s docstring, earliest first: each a list of units (`|` apart), each unit
    the folders or base modules it joins (`,`). The list is the paragraph after the one that starts
    "Layers,"; a line's names end where its description starts (two spaces or more)."""
    paragraphs = (depthq.__doc__ or "").split("\n\n")
    block = next(paragraphs[k + 1] for k, text in enumerate(paragraphs) if text.startswith("Layers,"))
    names = " ".join(re.split(r"\s{2,}", line.strip())[0] for line in block.splitlines() if line[4:5] != " ")
    layers = names.split("←")
    return [[tuple(n.strip() for n in unit.split(",")) for unit in layer.split("|")] for layer in layers]


LAYERS = _declared_layers()
# The package root runs before any module (it sets MUJOCO_GL) and may import only `depthq.sim`'s
# `__init__`, which registers the env by name; any module may import the root (for `__version__`).
ROOT_MAY_IMPORT = {"depthq.sim"}


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(SRC.rglob("*.py")):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


MODULES = _modules()


def _targets(node: ast.Import | ast.ImportFrom, module: str) -> list[str]:
    """The depthq modules an import statement loads (a `from` import of a submodule counts as it)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name.split(".")[0] == "depthq"]
    if node.level:  # relative: resolve against the importing module's package
        package = module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]
        base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1])
        name = f"{base}.{node.module}" if node.module else base
    else:
        name = node.module or ""
    if name.split(".")[0] != "depthq":
        return []
    return [f"{name}.{a.name}" if f"{name}.{a.name}" in MODULES else name for a in node.names]


def _imports(module: str, top_level_only: bool = False) -> set[str]:
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    nodes = []
    if top_level_only:  # what runs at import time: module statements, not function or class bodies
        stack = list(tree.body)
        while stack:
            node = stack.pop()
            if isinstance(node, ast.Import | ast.ImportFrom):
                nodes.append(node)
            elif not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                stack.extend(ast.iter_child_nodes(node))
    else:
        nodes = [n for n in ast.walk(tree) if isinstance(n, ast.Import | ast.ImportFrom)]
    return {t for n in nodes for t in _targets(n, module)}


def _folder(module: str) -> str:
    """The folder (or base module) a module is in: `depthq.blocks.heads` → blocks."""
    return module.split(".")[1]


FOLDERS = sorted({_folder(m) for m in MODULES if m != "depthq"})
# folder → (layer, unit): its position in the docstring's list
PLACE = {name: (k, ", ".join(unit)) for k, layer in enumerate(LAYERS) for unit in layer for name in unit}


def _folder_imports() -> dict[str, dict[str, list[str]]]:
    """folder → {folder it imports: the module imports that make the edge}, self-imports left out."""
    graph: dict[str, dict[str, list[str]]] = {f: {} for f in FOLDERS}
    for module in MODULES:
        if module == "depthq":
            continue
        for target in sorted(_imports(module) - {"depthq"}):
            if _folder(target) != _folder(module):
                graph[_folder(module)].setdefault(_folder(target), []).append(f"{module} → {target}")
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of more than one node (or a node that imports itself)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph[v]:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def test_the_docstring_lists_every_folder_once() -> None:
    names = [name for layer in LAYERS for unit in layer for name in unit]
    assert len(names) == len(set(names)), f"named twice in depthq's docstring: {names}"
    assert set(names) == set(FOLDERS), (
        f"folders in no layer: {sorted(set(FOLDERS) - set(names))}; "
        f"layers that are no folder: {sorted(set(names) - set(FOLDERS))}"
    )


def test_no_folder_imports_a_later_layer_or_a_sibling() -> None:
    bad = []
    for folder, targets in _folder_imports().items():
        layer, unit = PLACE[folder]
        for target, how in targets.items():
            target_layer, target_unit = PLACE[target]
            if target_unit != unit and target_layer >= layer:
                bad.append(f"{folder} imports {target}, a later layer or a sibling: {'; '.join(how)}")
    assert not bad, "layer order broken:\n" + "\n".join(sorted(bad))


def test_the_package_imports_no_experiment() -> None:
    """The experiments (research/, outside the wheel) are measurements behind the docs: they import the
    package, never the other way round, so nothing a verb runs depends on one."""
    found = [f"{m}: {t}" for m in MODULES for t in _imports(m) if t.split(".")[0] == "research"]
    assert not found, found


def test_no_folder_loop() -> None:
    graph = {folder: set(targets) for folder, targets in _folder_imports().items()}
    assert not _cycles(graph), f"folders that import each other round a loop: {_cycles(graph)}"


def test_the_root_imports_only_the_env_registration() -> None:
    assert _imports("depthq") <= ROOT_MAY_IMPORT
    assert _imports("depthq.sim") == set()  # so `import depthq` costs gymnasium, not mujoco or torch


def test_no_import_cycle_at_import_time() -> None:
    graph = {m: _imports(m, top_level_only=True) & MODULES.keys() for m in MODULES}
    assert not _cycles(graph), f"modules that import each other: {_cycles(graph)}"


def test_the_command_starts_without_mujoco_or_the_extras() -> None:
    """`depthq --help` builds every verb's parser; none may pay for MuJoCo, the optional extras or the
    report's plotting. (torch is loaded there today: `train`'s flag defaults come from torch modules.)"""
    heavy = ("mujoco", "ray", "onnx", "onnxruntime", "rosbags", "matplotlib", "scipy", "tensorboard")
    code = "import sys, depthq.cli; depthq.cli.build_parser(); "
    code += f"print([m for m in {heavy} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
