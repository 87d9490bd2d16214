"""The package's layers: each imports only the layers below it, no module imports itself
back through a circle, and neither does a top-level file or folder (docs/architecture.md
draws them).

The allowed direction is written once, in LAYERS (bottom first).  Every import is counted,
also those inside functions: a lazy import upwards is still an upward dependency.
"""

from __future__ import annotations

import ast
import pathlib

import pytest

import sliders

PACKAGE = pathlib.Path(sliders.__file__).parent

# bottom first; a module belongs to the first entry that is it or one of its parents
LAYERS = [
    # what everything may use: the chain's arithmetic, the keyed draws, the status codes
    ("base", ["sliders._version", "sliders.chain", "sliders.keyed_random", "sliders.status",
              "sliders.units"]),
    # the friction laws and loadings: their parameters, checks and physics, no scene
    ("parts", ["sliders.parts"]),
    # one configured run, composed of its parts
    ("scene", ["sliders.scene"]),
    # the steppers that advance a scene's chain (the reference and the kernel)
    ("engine", ["sliders.engine"]),
    ("io", ["sliders.io"]),
    ("simulation", ["sliders.preparation", "sliders.driver", "sliders.result"]),
    ("analysis", ["sliders.analysis"]),
    ("figures", ["sliders.figures"]),
    # the forecast and the posterior of a measured pile, the live follower: the commands' API
    ("forecasting", ["sliders.forecasting"]),
    ("runs", ["sliders.runs"]),
    # the commands users type and the package's front door
    ("entry", ["sliders", "sliders.__main__", "sliders._forward", "sliders.ensemble",
               "sliders.study", "sliders.merge", "sliders.reproduction", "sliders.forecast",
               "sliders.prior"]),
]


def module_name(path: pathlib.Path) -> str:
    parts = ["sliders", *path.relative_to(PACKAGE).with_suffix("").parts]
    return ".".join(parts[:-1]) if parts[-1] == "__init__" else ".".join(parts)


def modules() -> dict[str, pathlib.Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py")) if "__pycache__" not in p.parts}


def layer_of(module: str) -> int:
    best, depth = None, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for pre in prefixes:
            if (module == pre or module.startswith(pre + ".")) and pre.count(".") > depth:
                best, depth = i, pre.count(".")
    if best is None:
        raise AssertionError(f"{module} is in no layer: add it to LAYERS")
    return best


def imported(module: str, path: pathlib.Path, known: set[str]) -> set[str]:
    """The package modules that ``module`` imports (module level and inside functions)."""
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:  # "from . import observables" names a module
                sub = f"{target}.{alias.name}"
                out.add(sub if sub in known else target)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return {m for m in out if m in known and m != module}


def import_graph():
    mods = modules()
    known = set(mods) | {"sliders._kernel"}
    return {m: imported(m, p, known) for m, p in mods.items()}


def test_every_module_has_a_layer():
    for m in modules():
        layer_of(m)


def test_layers_import_only_downwards():
    graph = import_graph()
    upward = [f"{m} ({LAYERS[layer_of(m)][0]}) imports {t} ({LAYERS[layer_of(t)][0]})"
              for m, targets in graph.items() for t in targets
              if t != "sliders._kernel" and layer_of(t) > layer_of(m)]
    assert not upward, "\n".join(upward)


def circles(graph: dict[str, set[str]]) -> list[str]:
    """Every circle a depth-first walk of ``graph`` meets, as "a -> b -> a"."""
    state: dict[str, int] = {}
    stack: list[str] = []
    found: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                found.append(" -> ".join(stack[stack.index(t):] + [t]))
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    return found


def test_no_import_circles():
    graph = import_graph()
    # a package's __init__ imports its own modules (re-exports): that edge is structure, not a circle
    graph = {m: {t for t in ts if not t.startswith(m + ".")} for m, ts in graph.items()}
    found = circles(graph)
    assert not found, "\n".join(found)


def node_of(module: str) -> str:
    """The top-level file or folder of the package that holds ``module`` (a folder is one node)."""
    return ".".join(module.split(".")[:2])


def node_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The import graph of the package's top-level files and folders (each folder one node;
    imports inside a folder are not edges).  The package's own ``__init__`` (the front door,
    which imports from everywhere) is left out."""
    nodes: dict[str, set[str]] = {}
    for m, targets in graph.items():
        if m == "sliders":
            continue
        edges = nodes.setdefault(node_of(m), set())
        edges.update(node_of(t) for t in targets if t != "sliders" and node_of(t) != node_of(m))
    return nodes


def test_no_circles_between_top_level_files_and_folders():
    """A folder imported by a file that it imports itself would sit both below and above that
    file: each top-level file and folder of the package must be one place in the order."""
    found = circles(node_graph(import_graph()))
    assert not found, "\n".join(found)


def test_the_folder_rule_catches_a_loop_through_a_folder():
    """The check itself can fail: a folder whose modules import a file that imports another
    of its modules is a loop between the two nodes, though no module imports itself back."""
    graph = {"sliders.engine.reference": {"sliders.scene"},
             "sliders.engine.loading": {"sliders.chain"},
             "sliders.scene": {"sliders.engine.loading"}, "sliders.chain": set()}
    assert not circles(graph)
    assert circles(node_graph(graph)) == ["sliders.engine -> sliders.scene -> sliders.engine"]


@pytest.mark.parametrize("bad", ["sliders.analysis.observables", "sliders.runs.ensemble"])
def test_the_rule_catches_an_upward_import(bad, tmp_path):
    """The check itself can fail: an io module importing from a higher layer is reported."""
    known = set(modules())
    fake = PACKAGE / "io" / "storage.py"
    text = fake.read_text() + f"\nfrom ..{bad.split('.', 1)[1]} import x\n"
    p = tmp_path / "io" / "storage.py"
    p.parent.mkdir()
    p.write_text(text)
    found = imported("sliders.io.storage", p, known)
    assert bad in found and layer_of(bad) > layer_of("sliders.io.storage")


def test_every_public_name_is_documented():
    """Module-level functions and classes and the public members of every class (private
    classes included: their methods are what a reader of the scheduler meets) have docstrings."""
    missing = []
    for m, path in modules().items():
        tree = ast.parse(path.read_text())
        if ast.get_docstring(tree) is None:
            missing.append(f"{m} (module)")
        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
                if ast.get_docstring(node) is None:
                    missing.append(f"{m}.{node.name}")
            if isinstance(node, ast.ClassDef):
                for sub in node.body:
                    if (isinstance(sub, ast.FunctionDef) and not sub.name.startswith("_")
                            and ast.get_docstring(sub) is None):
                        missing.append(f"{m}.{node.name}.{sub.name}")
    assert not missing, "undocumented: " + ", ".join(missing)


#: the modules that may import by name: the forwarding of the commands users type and of the
#: package's front door (``sliders._forward``)
IMPORT_BY_NAME = {"sliders._forward"}


def imports_by_name(path: pathlib.Path, package: str) -> list[str]:
    """The ``importlib.import_module(...)`` calls of a module of ``package`` whose target is
    not a module of its own folder (an f-string ``{__package__}.NAME`` or ``{__name__}.NAME``,
    one name deep, in a folder below the package's top), as source."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "import_module" and node.args):
            arg = node.args[0]
            head = (arg.values[0].value.id if isinstance(arg, ast.JoinedStr) and arg.values
                    and isinstance(arg.values[0], ast.FormattedValue)
                    and isinstance(arg.values[0].value, ast.Name) else None)
            rest = "".join(v.value for v in getattr(arg, "values", [])[1:]
                           if isinstance(v, ast.Constant))
            own = (head == "__name__" or (head == "__package__" and package != "sliders")) \
                and rest.startswith(".") and rest.count(".") == 1
            if not own:
                out.append(ast.unparse(node))
    return out


def test_no_import_by_name_between_layers():
    """A module imports another layer's modules with import statements, never by a name built
    at run time: the import graph above sees every edge."""
    found = [f"{m}: {call}" for m, path in modules().items() if m not in IMPORT_BY_NAME
             for call in imports_by_name(path, m if path.name == "__init__.py"
                                         else m.rsplit(".", 1)[0])]
    assert not found, "\n".join(found)


def test_the_rule_catches_an_import_by_name(tmp_path):
    """The check itself can fail: a module reading another layer's module by its name, also
    through ``__package__`` (the front door's ``sliders.forecast`` did so), but not its own
    folder's."""
    p = tmp_path / "m.py"
    p.write_text("import importlib\n\ndef f(name):\n    return (importlib.import_module("
                 "f'{__package__}.x'), importlib.import_module('sliders.runs.forecast.infer'), "
                 "importlib.import_module(f'{__package__}.runs.forecast.{name}'))\n")
    assert imports_by_name(p, "sliders.runs.forecast") == [
        "importlib.import_module('sliders.runs.forecast.infer')",
        "importlib.import_module(f'{__package__}.runs.forecast.{name}')"]
    assert len(imports_by_name(p, "sliders")) == 3


def test_the_forecast_front_door_imports_the_forecasting_layer():
    """``sliders.forecast`` imports the forecasting layer with an import statement, and the
    layer imports nothing of the commands (``sliders.runs``) nor of the front doors."""
    graph = import_graph()
    assert {"sliders.forecasting.predict", "sliders.forecasting.infer"} <= graph["sliders.forecast"]
    up = [f"{m} imports {t}" for m, ts in graph.items() if m.startswith("sliders.forecasting")
          for t in ts if layer_of(t) > layer_of("sliders.forecasting")]
    assert not up, "\n".join(up)
