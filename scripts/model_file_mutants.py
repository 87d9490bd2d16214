"""Each check of a model file's reader disabled in turn: do the crafted-file tests notice?

The checks are those in the code ``tests/test_code_shape.py`` counts as reading and checking
a model file (``tests/helpers.MODEL_FILE_READING``): each ``require(ok, ...)`` (ok -> True),
each tree check ``none(bad, ...)`` (bad -> nothing bad), each ``(bad, what)`` of
``ModelArchive.refuse_if`` (bad -> False), each ``if`` whose body raises ``ModelFileError``
or ``IntegrityError`` (never taken), and each declared part of an estimator (a key of its
``FIELDS``, dropped; the evaluators' declarations also build them, and are left).  One mutant
at a time is written into the source, the model-file tests run until their first failure, and
the source is restored.  A mutant they pass ("survived") is a check no test asks for.

It rewrites the sources it tests: run it in a scratch clone with its own environment::

    git clone -q . /tmp/mutants && cd /tmp/mutants && bash scripts/setup.sh
    .venv/bin/python scripts/model_file_mutants.py --out mutants.tsv

Prints a line per mutant and the counts, and writes the table (``--out``, tab-separated; a run
stopped is resumed from it).  A tree with uncommitted changes is refused.  About 40 s a mutant
the tests notice and 90 s one they do not, on one core.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import os
import pathlib
import re
import subprocess
import sys
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from helpers import MODEL_FILE_READING  # noqa: E402 (the code tests/test_code_shape.py counts)

#: the model-file tests, the quickest to fail first
TESTS = ["tests/test_trust_model_file.py::test_every_part_a_forecast_reads_is_checked_by_its_name",
         "tests/test_model_arrays.py", "tests/test_trust_posterior_file.py",
         "tests/test_trust_model_file.py", "tests/test_forecast_model.py"]
#: a test run past this is a mutant that hangs
TIMEOUT_S = 600
RAISED = {"ModelFileError", "IntegrityError"}
COLUMNS = ("id", "kind", "where", "check", "result", "seconds", "first_failure")


def targets() -> dict:
    """``{module path: [qualified names]}`` of ``MODEL_FILE_READING`` ("" for a whole module)."""
    out: dict = {}
    for entry in MODEL_FILE_READING:
        module, _, name = entry.partition(":")
        out.setdefault(module, []).append(name)
    return out


def named(tree) -> dict:
    """``{qualified name: node}`` of a module's functions, classes and assignments."""
    out = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            target = child.targets[0] if isinstance(child, ast.Assign) else None
            name = getattr(child, "name", None) or getattr(target, "id", None)
            if name and isinstance(child, (ast.FunctionDef, ast.ClassDef, ast.Assign)):
                out[f"{prefix}{name}"] = child
                if isinstance(child, ast.ClassDef):
                    visit(child, f"{prefix}{name}.")
    visit(tree, "")
    return out


def mutants() -> list[dict]:
    """Every mutant, in a stable order: its id, kind (a-e), file, line, the check's text, and
    the source with it disabled (bytes: ``ast`` counts columns in UTF-8 bytes)."""
    rows = []

    def add(kind, path, line, check, source):
        rows.append({"kind": kind, "path": path, "line": line,
                     "check": " ".join(check.split())[:100], "source": source})

    for module, names in targets().items():
        path = ROOT / "src" / pathlib.Path(*module.split(".")).with_suffix(".py")
        data = path.read_bytes()
        starts = [0]
        for line in data.splitlines(keepends=True):
            starts.append(starts[-1] + len(line))
        tree = ast.parse(data)
        nodes = named(tree)

        def disabled(kind, node, new):
            a = starts[node.lineno - 1] + node.col_offset
            b = starts[node.end_lineno - 1] + node.end_col_offset
            add(kind, path, node.lineno, data[a:b].decode(), data[:a] + new + data[b:])

        for name in names:
            for node in ast.walk(nodes[name] if name else tree):
                call = isinstance(node, ast.Call) and getattr(node.func, "id", None)
                if call == "require" and node.args:
                    disabled("a", node.args[0], b"True")
                elif call == "none" and node.args:
                    disabled("b", node.args[0], b"np.zeros(1, bool)")
                elif isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "refuse_if":
                    for arg in node.args:
                        disabled("c", arg.elts[0], b"False")
                elif isinstance(node, ast.If) and any(
                        isinstance(s, ast.Raise) and isinstance(s.exc, ast.Call)
                        and getattr(s.exc.func, "id", None) in RAISED for s in node.body):
                    disabled("d", node.test, b"False")
            if name.endswith("FIELDS") and not module.endswith("evaluators"):
                owner = importlib.import_module(module)
                for part in name.split("."):
                    owner = getattr(owner, part)
                node, attr = nodes[name], name.split(".")[-1]
                end = starts[node.end_lineno]
                for key in owner:
                    drop = (f"{' ' * node.col_offset}{attr} = {{k: v for k, v in {attr}.items() "
                            f"if k != {key!r}}}\n").encode()
                    add("e", path, node.lineno, f"{name} entry {key!r}",
                        data[:end] + drop + data[end:])
    rows.sort(key=lambda r: (r["kind"] == "e", str(r["path"]), r["line"], r["check"]))
    for i, r in enumerate(rows):
        r["id"] = f"M{i:03d}"
    return rows


def run(row) -> tuple[str, float, str]:
    """``(result, seconds, first failing test)`` of the tests with ``row``'s mutant written."""
    original = row["path"].read_bytes()
    row["path"].write_bytes(row["source"])
    t0 = time.monotonic()
    try:
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:randomly", "-n",
                               "0", "-x", *TESTS], cwd=ROOT, capture_output=True, text=True,
                              timeout=TIMEOUT_S, env={**os.environ, "PYTHONDONTWRITEBYTECODE": "1"})
        code, out = done.returncode, done.stdout
    except subprocess.TimeoutExpired:
        code, out = None, ""
    finally:
        row["path"].write_bytes(original)
    seconds = time.monotonic() - t0
    failed = re.findall(r"^(?:FAILED|ERROR) (\S+)", out, re.M)
    if code == 0:
        return "survived", seconds, ""
    return ("killed", seconds, failed[0]) if code == 1 and failed else (
        "broken", seconds, "timeout" if code is None else f"exit {code}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="model_file_mutants.py", description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=pathlib.Path, default=pathlib.Path("mutants.tsv"),
                    help="the table written, and read back to resume (default: mutants.tsv)")
    ap.add_argument("--kinds", default="abcde", help="the kinds of mutant run (default: abcde)")
    ap.add_argument("--only", nargs="+", metavar="ID", help="run these mutants alone (M000 ...)")
    ap.add_argument("--list", action="store_true", help="list the mutants, run none")
    args = ap.parse_args(argv)
    rows = mutants()
    if args.list:
        for r in rows:
            print(r["id"], r["kind"], f"{r['path'].relative_to(ROOT)}:{r['line']}", r["check"],
                  sep="\t")
        return 0
    if subprocess.run(["git", "diff", "--quiet"], cwd=ROOT).returncode != 0:
        sys.exit("model_file_mutants.py: the tree has uncommitted changes; run it in a clean "
                 "scratch clone (it rewrites the sources it tests)")
    done = {}
    if args.out.exists():
        done = {c[0]: c for c in (line.split("\t") for line in
                                  args.out.read_text(encoding="utf-8").splitlines()[1:])}
    else:
        args.out.write_text("\t".join(COLUMNS) + "\n", encoding="utf-8")
    for r in rows:
        chosen = r["kind"] in args.kinds and (not args.only or r["id"] in args.only)
        if r["id"] in done or not chosen:
            continue
        result, seconds, first = run(r)
        cells = (r["id"], r["kind"], f"{r['path'].relative_to(ROOT)}:{r['line']}", r["check"],
                 result, f"{seconds:.0f}", first)
        with args.out.open("a", encoding="utf-8") as fh:
            fh.write("\t".join(cells) + "\n")
        done[r["id"]] = cells
        print(*cells, sep="  ", flush=True)
    results = [c[4] for c in done.values()]
    print(f"{len(results)} mutants: " + ", ".join(
        f"{results.count(k)} {k}" for k in ("killed", "survived", "broken")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
