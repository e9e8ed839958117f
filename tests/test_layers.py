"""The package's layers hold: no module imports one of a later layer (the order is `depthq`'s docstring),
and no two modules import each other at import time. Read from the source with `ast`, imports inside
functions included: a lazy import is a dependency too."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import depthq

SRC = Path(depthq.__file__).parent

# Earlier layers first. A module may import modules of its own unit and of earlier layers; two units
# in one layer are independent (neither imports the other). The longest matching prefix decides, so
# control's learned policies sit above `nets`, the rest of control below `data` (collection drives the
# exploration policy). Keep in step with the order in `depthq`'s docstring.
LAYERS: list[dict[str, tuple[str, ...]]] = [
    # imports no layer
    {"base": ("depthq.errors", "depthq.configio", "depthq.parallel", "depthq.flags", "depthq.host")},
    {"sim": ("depthq.sim",)},
    {"control": ("depthq.control",)},  # the Policy interface, exploration (OU), expert (heuristic)
    {"data": ("depthq.data",)},
    {"nets": ("depthq.nets",)},
    {"policies": ("depthq.control.qnet_policy", "depthq.control.onnx_policy", "depthq.control.registry")},
    {"train": ("depthq.train",)},
    {"evaluate": ("depthq.evaluate",), "deploy": ("depthq.deploy",)},
    {"report": ("depthq.report",), "bench": ("depthq.bench",)},
    {"scripts": ("depthq.scripts",)},
    {"cli": ("depthq.cli",)},
    {"experiments": ("depthq.experiments",)},  # measurements behind the docs, driving the verbs
]
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


def _unit(module: str) -> tuple[int, str]:
    """(layer, unit) of a module: the unit with the longest prefix matching it."""
    best = (-1, "", "")
    for layer, units in enumerate(LAYERS):
        for unit, prefixes in units.items():
            for prefix in prefixes:
                if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > len(best[2]):
                    best = (layer, unit, prefix)
    assert best[0] >= 0, f"{module} is in no layer: add it to LAYERS here and to depthq's docstring"
    return best[0], best[1]


def test_every_module_is_in_a_layer() -> None:
    for module in MODULES:
        if module != "depthq":
            _unit(module)


def test_no_module_imports_a_later_layer_or_a_sibling() -> None:
    bad = []
    for module in MODULES:
        if module == "depthq":
            continue
        layer, unit = _unit(module)
        for target in _imports(module) - {"depthq"}:
            target_layer, target_unit = _unit(target)
            if target_unit != unit and target_layer >= layer:
                bad.append(f"{module} ({unit}) imports {target} ({target_unit})")
    assert not bad, "layer order broken:\n" + "\n".join(sorted(bad))


def test_the_root_imports_only_the_env_registration() -> None:
    assert _imports("depthq") <= ROOT_MAY_IMPORT
    assert _imports("depthq.sim") == set()  # so `import depthq` costs gymnasium, not mujoco or torch


def test_no_import_cycle_at_import_time() -> None:
    """Tarjan's strongly connected components over module-level imports: each must be one module."""
    graph = {m: _imports(m, top_level_only=True) & MODULES.keys() for m in MODULES}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    cycles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
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

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, f"modules that import each other: {cycles}"


def test_the_command_starts_without_mujoco_or_the_extras() -> None:
    """`depthq --help` builds every verb's parser; none may pay for MuJoCo, the optional extras or the
    report's plotting. (torch is loaded there today: `train`'s flag defaults come from torch modules.)"""
    heavy = ("mujoco", "ray", "onnx", "onnxruntime", "rosbags", "matplotlib", "scipy", "tensorboard")
    code = "import sys, depthq.cli; depthq.cli.build_parser(); "
    code += f"print([m for m in {heavy} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
