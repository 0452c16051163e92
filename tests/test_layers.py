"""The package's architecture, checked from its source (ast, nothing imported): each folder is one
layer, imports (top-level and lazy ones inside functions alike) go down the layers only, there is
no import cycle between modules, and the kernels import nothing but kernels.

    cli -> api -> workflows -> studies -> plots, export -> analysis -> driver -> io -> model
        -> config, units, errors, config_doc -> kernels (and the package root, which picks numba's cache)

One edge goes up on purpose: the package root names the Python API (``gouge_cli.open_run`` ...)
through a PEP 562 ``__getattr__`` that imports gouge_cli.api on first use (FACADE).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "gouge_cli"
RANK = {"kernels": 0, "": 0, "errors": 1, "units": 1, "config": 1, "config_doc": 1, "model": 2, "io": 3,
        "driver": 4, "analysis": 5, "plots": 6, "export": 6, "studies": 7, "workflows": 8, "api": 9, "cli": 10}
FACADE = {("gouge_cli", "gouge_cli.api")}      # the root's lazy re-export of the API (module docstring)


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in PACKAGE.rglob("*.py")}


def imports(name: str, path: Path, known: set[str]) -> set[str]:
    """gouge_cli modules `name` imports anywhere in its source, lazy imports included, ``if TYPE_CHECKING``
    blocks excluded (`from . import x` counts x if it is a module)."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    tree = ast.parse(path.read_text())
    typing_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If)
                   and getattr(block.test, "id", None) == "TYPE_CHECKING" for n in ast.walk(block)}
    for node in ast.walk(tree):
        if id(node) in typing_only:         # annotations only: no import at run time
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("gouge_cli"):
                continue
            subs = {f"{target}.{a.name}" for a in node.names} & known
            found |= subs or {target}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name.startswith("gouge_cli")}
    return {m for m in found if m in known and m != name}


def layer(name: str) -> str:
    parts = name.split(".")[1:]
    return parts[0] if parts else ""


def graph() -> dict[str, set[str]]:
    mods = modules()
    return {name: {t for t in imports(name, path, set(mods)) if (name, t) not in FACADE} for name, path in mods.items()}


def test_every_module_is_in_a_layer():
    assert {layer(m) for m in modules()} <= set(RANK)


def test_imports_go_down_the_layers():
    upward = [f"{m} ({layer(m)}) imports {t} ({layer(t)})" for m, targets in graph().items() for t in targets
              if RANK[layer(t)] > RANK[layer(m)]]
    assert not upward, "\n".join(sorted(upward))


def test_kernels_import_only_kernels():
    outside = [f"{m} imports {t}" for m, targets in graph().items() if layer(m) == "kernels"
               for t in targets if layer(t) != "kernels"]
    assert not outside, outside


def test_no_import_cycle():
    g = graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(g[node]):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for node in sorted(g):
        if node not in state:
            visit(node, [])
    assert not cycles, "\n".join(cycles)


def test_no_private_kernel_called_from_outside_the_kernels():
    calls = []
    for name, path in modules().items():
        if layer(name) == "kernels":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and "kernels" in node.module:
                calls += [f"{name} imports {a.name}" for a in node.names if a.name.startswith("_")]
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                    and isinstance(node.value, ast.Name) and node.value.id in ("K", "L", "M", "KD", "KP", "KG", "KF")):
                calls.append(f"{name}: {node.value.id}.{node.attr}")
    assert not calls, calls
