"""Count the private names (``_x``) one module of the package imports from another.

    python scripts/private_imports.py [src/sliders]

Prints the count, then one line per import: ``importer: module.name``.  A
private name crossing a module boundary is a sign that the code it names
wants to be public, or to move.
"""

from __future__ import annotations

import ast
import pathlib
import sys


def private_imports(root: pathlib.Path) -> list[str]:
    """``importer: module.name`` for every private name imported from another module of ``root``."""
    hits = []
    for path in sorted(root.rglob("*.py")):
        module = ".".join(path.relative_to(root.parent).with_suffix("").parts)
        package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                parts = package.split(".")
                target = ".".join(parts[:len(parts) - node.level + 1] + [node.module or ""])
            else:
                target = node.module or ""
            if target.rstrip(".").split(".")[0] != root.name:
                continue
            hits += [f"{module}: {target.rstrip('.')}.{a.name}" for a in node.names
                     if a.name.startswith("_") and not a.name.startswith("__")]
    return hits


if __name__ == "__main__":
    found = private_imports(pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "src/sliders"))
    print(len(found))
    print("\n".join(found))
