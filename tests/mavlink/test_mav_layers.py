"""cosim.mavlink is a layer: it builds on the kernel (cosim.core, cosim.errors,
cosim.guidance) and nothing above it. The vehicle classes build on it and
hand their specifics down (personality, safety rule); the scenario loader
calls its section parser; the runner builds its links."""

from __future__ import annotations

import ast
from pathlib import Path

import cosim.mavlink

#: what cosim.mavlink may import of cosim (besides itself)
BELOW = ("cosim.core", "cosim.errors", "cosim.guidance")


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import of ``path``, inside functions too, not
    those under ``if TYPE_CHECKING:``."""
    tree = ast.parse(path.read_text(), str(path))
    typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                   and "TYPE_CHECKING" in ast.unparse(node.test)
                   for b in node.body for n in ast.walk(b)}
    out = []
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f"{path}:{node.lineno}: a relative import"
            out.append((node.lineno, node.module or ""))
    return out


def test_mavlink_imports_only_the_kernel_and_itself() -> None:
    root = Path(cosim.mavlink.__file__).parent
    above = [f"{p.relative_to(root.parent.parent)}:{line}: {module}"
             for p in sorted(root.rglob("*.py")) for line, module in _imports(p)
             if module.split(".")[0] == "cosim" and module != "cosim"
             and not module.startswith(("cosim.mavlink", *BELOW))]
    assert not above, "cosim.mavlink imports parts above it:\n" + "\n".join(above)
