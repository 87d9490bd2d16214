"""No Python function of the package is longer than a reader can hold: at most
MAX_CODE_LINES lines of code.

Lines of code of a function: the physical lines from its ``def`` to its last line that
carry a Python token (a multi-line string or bracket counts every line it spans), less
the lines of its docstring.  Blank lines and lines holding only a comment do not count;
a nested function counts inside the function that holds it (and once more on its own).
"""

from __future__ import annotations

import ast
import importlib.util
import io
import pathlib
import tokenize

import pytest

import sliders

from helpers import MODEL_FILE_READING

PACKAGE = pathlib.Path(sliders.__file__).parent
MAX_CODE_LINES = 80

# Functions allowed to stay longer than MAX_CODE_LINES (none): an entry names one
# that is being shortened, and the second test below fails once it is short.
STILL_LONG: set[str] = set()

_NOT_CODE = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
             tokenize.ENDMARKER, tokenize.ENCODING}


def code_lines(source: str) -> set[int]:
    """Line numbers (1-based) of ``source`` that carry a Python token other than a comment."""
    lines: set[int] = set()
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type not in _NOT_CODE:
            lines.update(range(tok.start[0], tok.end[0] + 1))
    return lines


def _docstring_lines(node: ast.AST) -> set[int]:
    body = getattr(node, "body", [])
    if (body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
            and isinstance(body[0].value.value, str)):
        return set(range(body[0].lineno, body[0].end_lineno + 1))
    return set()


def function_lengths(source: str, module: str) -> dict[str, int]:
    """Lines of code of every function of ``source``, by qualified name ``module:Outer.inner``."""
    tree = ast.parse(source)
    code = code_lines(source)
    out: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}.{child.name}" if prefix else child.name
                if not isinstance(child, ast.ClassDef):
                    span = set(range(child.lineno, child.end_lineno + 1))
                    out[f"{module}:{name}"] = len((span & code) - _docstring_lines(child))
                visit(child, name)
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def package_function_lengths() -> dict[str, int]:
    """Lines of code of every function of the installed package."""
    out: dict[str, int] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        if "__pycache__" in path.parts:
            continue
        module = ".".join(["sliders", *path.relative_to(PACKAGE).with_suffix("").parts])
        out.update(function_lengths(path.read_text(encoding="utf-8"), module))
    return out


def test_no_function_is_too_long():
    long = {name: n for name, n in package_function_lengths().items() if n > MAX_CODE_LINES}
    new = {name: n for name, n in long.items() if name not in STILL_LONG}
    assert not new, (f"functions over {MAX_CODE_LINES} lines of code: "
                     + ", ".join(f"{name} ({n})" for name, n in sorted(new.items())))


def test_the_allow_list_names_only_long_functions():
    """An entry of STILL_LONG whose function became short (or went) is removed from it."""
    lengths = package_function_lengths()
    stale = sorted(name for name in STILL_LONG if lengths.get(name, 0) <= MAX_CODE_LINES)
    assert not stale, "short now, remove from STILL_LONG: " + ", ".join(stale)


def test_the_count_skips_docstrings_comments_and_blank_lines():
    source = '''
def f(x):
    """A docstring
    of three lines.
    """
    # a comment

    y = (x +
         1)  # two lines of one statement
    return f"""{y}
    """
'''
    assert function_lengths(source, "m") == {"m:f": 5}


def test_a_long_function_is_reported():
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_CODE_LINES))
    source = f"class C:\n    def g(self):\n        def h():\n{body.replace('    ', '            ')}" \
             "            return 0\n        return h\n"
    lengths = function_lengths(source, "m")
    assert lengths["m:C.g.h"] == MAX_CODE_LINES + 2
    assert lengths["m:C.g"] == MAX_CODE_LINES + 4


# ---------------------------------------------------------------------------
# imports at the top of modules
# ---------------------------------------------------------------------------
# A module's imports are at its top, where a reader sees what it needs.  An import inside a
# function is allowed for these modules only (the module, or a parent of it), each for its reason:
LAZY_IMPORTS = {
    "h5py": "HDF5 (0.1 s): the commands and readers that open no file (--help, predict) skip it",
    "PIL": "the palette of a PNG, imported when a figure is saved",
    "sliders.figures": "the figures import matplotlib (0.3 s and a backend) at their top: "
                       "the commands import them when a figure is drawn",
    "sklearn": "scikit-learn (2 s): the forecast parser and the run commands do not need it",
    "sklearn.ensemble": "scikit-learn (2 s), imported by the forecaster that fits with it",
    "sliders.analysis.forecast": "the forecasters and their features (a tenth of a second): "
                                 "sliders.forecast, the forecast parser and the picture "
                                 "import them when a forecast is made",
    "threadpoolctl": "scikit-learn's threads, held to one while the posterior is fitted",
    "crepes": "the conformal calibration, imported by the learned forecaster that fits it",
    "mpi4py": "importing it starts MPI: a serial run never does",
    "importlib.metadata": "the installed distributions' versions (18 ms), read when a file's "
                          "provenance is written: the forecast parser's --help does not need it",
    "scipy": "imported by the one statistic that needs it",
    "sliders.forecasting.infer": "the posterior and its piles' simulation (the scene, 50 ms): "
                                 "a forecast's model imports it at its first inference",
    "sliders._kernel": "the compiled kernel is optional: the NumPy reference runs without it",
}
# Modules whose function-level imports wait for a change that moves the modules they import
# (the scene's parts, the tilt file): an entry names one, the second test below fails once it
# holds no function-level import outside LAZY_IMPORTS.
STILL_LAZY: set[str] = set()
#: the most function-level imports the package holds (all of them allowed); it may only fall
MAX_FUNCTION_IMPORTS = 54


def function_imports(source: str, package: list[str]) -> list[tuple[int, str]]:
    """(line, module imported) of every import inside a function of ``source``, a module of
    ``package`` (its dotted name's parts; relative imports made absolute)."""
    out = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            if in_function and isinstance(child, ast.Import):
                out.extend((child.lineno, a.name) for a in child.names)
            elif in_function and isinstance(child, ast.ImportFrom):
                base = package[:len(package) - child.level + 1] if child.level else []
                target = ".".join(base + ([child.module] if child.module else []))
                if child.module is None:  # "from .. import _kernel" names a module
                    out.extend((child.lineno, f"{target}.{a.name}") for a in child.names)
                else:
                    out.append((child.lineno, target))
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)))

    visit(ast.parse(source), False)
    return out


def _allowed(module: str) -> bool:
    return any(module == m or module.startswith(m + ".") for m in LAZY_IMPORTS)


def _function_imports() -> dict[str, list[tuple[int, str]]]:
    return {str(p.relative_to(PACKAGE)): function_imports(
                p.read_text(), ["sliders", *p.relative_to(PACKAGE).parent.parts])
            for p in sorted(PACKAGE.rglob("*.py")) if "__pycache__" not in p.parts}


def test_imports_inside_functions_are_the_listed_lazy_ones():
    hidden = [f"{name}:{line}: {module}" for name, found in _function_imports().items()
              if name not in STILL_LAZY for line, module in found if not _allowed(module)]
    assert not hidden, "imports inside functions (move them to the top, or list the module " \
                       "in LAZY_IMPORTS with its reason):\n" + "\n".join(hidden)


def test_the_still_lazy_modules_hold_hidden_imports():
    found = _function_imports()
    done = [name for name in STILL_LAZY if all(_allowed(m) for _, m in found[name])]
    assert not done, f"no longer lazy, drop from STILL_LAZY: {done}"


def test_every_listed_lazy_import_is_used():
    used = {m for found in _function_imports().values() for _, m in found}
    unused = [m for m in LAZY_IMPORTS if not any(u == m or u.startswith(m + ".") for u in used)]
    assert not unused, f"listed as lazy but imported at the top everywhere: {unused}"


def test_function_level_imports_do_not_grow():
    count = sum(len(found) for found in _function_imports().values())
    assert count <= MAX_FUNCTION_IMPORTS, f"{count} imports inside functions"


def test_the_import_count_sees_relative_and_nested_imports():
    source = ("import os\n\ndef f():\n    from ..io import safeio\n    def g():\n"
              "        import h5py\n        from .. import _kernel\n    return g\n")
    assert function_imports(source, ["sliders", "runs"]) == [
        (4, "sliders.io"), (6, "h5py"), (7, "sliders._kernel")]
    assert not _allowed("sliders.io") and _allowed("h5py") and _allowed("sklearn.metrics")


# ---------------------------------------------------------------------------
# the reading and checking of a model file
# ---------------------------------------------------------------------------
#: the most non-blank lines MODEL_FILE_READING may hold; it may only fall
MAX_MODEL_FILE_READING_LINES = 655


def nonblank_lines(source: str) -> dict[str, int]:
    """Non-blank lines (docstrings and comments included) of ``source`` (key "") and of each of
    its functions, classes and assignments, by qualified name."""
    lines = source.splitlines()
    out = {"": sum(1 for line in lines if line.strip())}

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            target = (child.targets[0] if isinstance(child, ast.Assign)
                      else getattr(child, "target", None))
            name = getattr(child, "name", None) or getattr(target, "id", None)
            if isinstance(child, (ast.FunctionDef, ast.ClassDef, ast.Assign, ast.AnnAssign)) \
                    and name:
                qual = f"{prefix}.{name}" if prefix else name
                span = lines[child.lineno - 1:child.end_lineno]
                out[qual] = sum(1 for line in span if line.strip())
                if isinstance(child, ast.ClassDef):
                    visit(child, qual)

    visit(ast.parse(source), "")
    return out


def test_the_count_of_nonblank_lines_sees_functions_classes_and_fields():
    source = 'X = 1\n\nclass C:\n    """Doc."""\n\n    FIELDS = {\n        "a": 1}\n' \
             '    def f(self):\n        # a comment\n\n        return 2\n'
    assert nonblank_lines(source) == {"": 8, "X": 1, "C": 7, "C.FIELDS": 2, "C.f": 3}


def test_the_reading_and_checking_of_a_model_file_does_not_grow():
    """The code a model file's trust rests on (``MODEL_FILE_READING``) is read in full by
    whoever audits it: each class declares its fitted parts (``FIELDS``) for one checker
    (``integrity.check_fields``), with code of its own only for what a declaration cannot say.
    The goal is 344 lines; the bound holds what was reached and may only fall."""
    counts = {}
    for entry in MODEL_FILE_READING:
        module, _, name = entry.partition(":")
        path = PACKAGE.joinpath(*module.split(".")[1:]).with_suffix(".py")
        counts[entry] = nonblank_lines(path.read_text(encoding="utf-8"))[name]
    total = sum(counts.values())
    assert total <= MAX_MODEL_FILE_READING_LINES, (
        f"{total} lines read and check a model file: " + ", ".join(
            f"{e} ({n})" for e, n in sorted(counts.items(), key=lambda kv: -kv[1])[:8]))


@pytest.mark.slow  # 130 sources compiled
def test_each_check_of_the_model_file_reader_is_disabled_alone_by_the_mutation_script():
    """``scripts/model_file_mutants.py`` finds checks of every kind in the counted code, and
    each of its mutants is Python that differs from its source by one check disabled."""
    spec = importlib.util.spec_from_file_location(
        "model_file_mutants", PACKAGE.parents[1] / "scripts" / "model_file_mutants.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    rows = script.mutants()
    assert {r["kind"] for r in rows} == set("abcde") and len(rows) > 100
    assert len({r["id"] for r in rows}) == len(rows)
    for r in rows:
        original = r["path"].read_bytes()
        compile(r["source"], str(r["path"]), "exec")
        assert r["source"] != original and len(r["source"]) - len(original) < 120, r["check"]
    requires = [r for r in rows if r["kind"] == "a"]
    assert all(b"require(True" in r["source"] for r in requires)
