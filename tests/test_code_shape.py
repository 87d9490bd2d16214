"""No Python function of the package is longer than a reader can hold: at most
MAX_CODE_LINES lines of code.

Lines of code of a function: the physical lines from its ``def`` to its last line that
carry a Python token (a multi-line string or bracket counts every line it spans), less
the lines of its docstring.  Blank lines and lines holding only a comment do not count;
a nested function counts inside the function that holds it (and once more on its own).
"""

from __future__ import annotations

import ast
import io
import pathlib
import tokenize

import sliders

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
