"""The package is layered (docs/architecture.md): a part imports only the parts
of the layers below it, and no two modules import each other, imports inside
functions counted (those under ``if TYPE_CHECKING:`` are not: they are for
the type checker only). Read from the source, as the imports are written."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "cosim"

#: the layers, from the bottom (docs/architecture.md); a part may import its own
#: layer's other parts only where listed in SIDEWAYS
LAYERS: list[tuple[str, ...]] = [
    ("errors",),
    ("core",),
    ("guidance", "rigid", "world"),
    ("coverage", "mavlink"),
    ("vehicles",),
    ("fdm_pool", "scenario"),
    ("logs",),
    ("analysis", "conspicuity", "export", "sync"),
    ("bench", "renderer", "swarm", "sweep"),
    ("api", "search", "trials"),
    ("__init__",),
    ("cli",),
    ("__main__",),
]
SIDEWAYS: set[tuple[str, str]] = set()


def _modules() -> dict[str, Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        rel = p.relative_to(ROOT.parent).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        out[name] = p
    return out


def _imports(mods: dict[str, Path]) -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        tree = ast.parse(p.read_text())
        skip = set()
        for n in ast.walk(tree):
            if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test):
                skip.update(id(x) for b in n.body for x in ast.walk(b))
        pkg = m if p.name == "__init__.py" else m.rsplit(".", 1)[0]
        for n in ast.walk(tree):
            if id(n) in skip:
                continue
            if isinstance(n, ast.ImportFrom):
                base = n.module or ""
                if n.level:
                    parts = pkg.split(".")[: len(pkg.split(".")) - n.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base
                           for a in n.names]
            elif isinstance(n, ast.Import):
                targets = [a.name for a in n.names]
            else:
                continue
            for t in targets:
                while t and t not in mods and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in mods and t != m and t.startswith("cosim"):
                    edges[m].add(t)
    return edges


def _part(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_every_part_imports_only_the_layers_below() -> None:
    layer = {part: i for i, parts in enumerate(LAYERS) for part in parts}
    mods = _modules()
    unknown = sorted({_part(m) for m in mods} - set(layer))
    assert not unknown, f"parts missing from the layers (docs/architecture.md): {unknown}"
    bad = []
    for a, targets in _imports(mods).items():
        for b in targets:
            pa, pb = _part(a), _part(b)
            if pa == pb or (pa, pb) in SIDEWAYS:
                continue
            if layer[pb] >= layer[pa]:
                bad.append(f"{a} imports {b}: {pb} is not below {pa}")
    assert not bad, "\n".join(sorted(bad))


def test_no_two_modules_import_each_other() -> None:
    edges = _imports(_modules())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
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
                circles.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    assert not circles, "modules that import each other: " + "; ".join(
        " <-> ".join(c) for c in circles)
