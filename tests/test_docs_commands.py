"""Every command on every page runs as written, page by page, in a fresh folder.

The pages (README.md, docs/**/*.md, mpi_runs/README.md) are read by Sybil
(https://sybil.readthedocs.io), which finds their fenced blocks; this file
only says how each kind of block runs:

* ```` ```bash ````: the block is one bash script (``set -euo pipefail``) run in
  the page's folder; it must exit 0.
* ```` ```console ````: ``$ command`` lines, each followed by the output the page
  shows; the command must exit 0 and print that output (``...`` stands for
  any text, whitespace runs compare equal: doctest's ELLIPSIS and
  NORMALIZE_WHITESPACE).
* ```` ```pycon ```` and ```` ```python ````: Python in one namespace per page,
  ``>>>`` examples as doctests (their printed outputs compared).
* ``<!-- skip: next "why" -->`` before a block leaves it out, with the reason
  in the page's source (the set-up and test commands, which run this suite).

Any other fence (``text``, ``toml``, ``csv`` ...) shows text and is not run; a
block whose first line reads as a command must use one of the four above,
and an indented code block is refused (tests below), so nothing escapes.

The page's folder is fresh for every page and holds what a user's checkout
holds next to the commands: copies of ``mpi_runs/``, ``benchmarks/`` (without
its results) and ``scripts/``, and ``.venv`` (the Python running the tests).
Blocks run in the page's order; a failure names the page, the line of the
block, the command and the end of its output.  Pages with ``sbatch`` run
against the session's local SLURM (the ``slurm`` fixture of conftest.py).
"""

from __future__ import annotations

import doctest
import os
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path
from unittest import SkipTest

import pytest
from markdown_it import MarkdownIt
from sybil import Sybil
from sybil.evaluators.python import PythonEvaluator
from sybil.parsers.markdown import CodeBlockParser, PythonCodeBlockParser, SkipParser

from conftest import cpu_seconds

ROOT = Path(__file__).resolve().parents[1]
DOCTEST_FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
RUN_LANGUAGES = ("bash", "console", "pycon", "python")
BLOCK_TIMEOUT = 300  # seconds; the pages' small-size switches keep every block far below
COPIED = ("mpi_runs", "benchmarks", "scripts")  # small text trees the commands name
NOT_COPIED = shutil.ignore_patterns("results", "__pycache__", "*.pyc")
# the first line of a block that is a command (in a fence that would not run it)
COMMAND_START = re.compile(r"^\s*(\$ |python3? |\.venv/|bash |mpirun |sbatch |srun |pip )")


def pages() -> list[Path]:
    """The pages a reader follows: README, every Markdown page of docs/, mpi_runs/README.md."""
    docs = sorted(p for p in (ROOT / "docs").rglob("*.md")
                  if not {"_build", "generated"} & set(p.relative_to(ROOT).parts))
    return [ROOT / "README.md", *docs, ROOT / "mpi_runs" / "README.md"]


def page_id(page: Path) -> str:
    return str(page.relative_to(ROOT))


# ---- how each block runs ------------------------------------------------------------


def _shell_env() -> dict[str, str]:
    bindir = os.path.dirname(sys.executable)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLIDERS_", "PYTEST_"))}
    env.update(PATH=f"{bindir}:{env.get('PATH', '')}:/usr/sbin:/sbin", MPLBACKEND="Agg")
    return env


def _run_shell(example, script: str) -> subprocess.CompletedProcess:
    env = dict(example.namespace["__env__"])
    started = time.monotonic()
    res = subprocess.run(["bash", "-c", "set -euo pipefail\n" + script], cwd=os.getcwd(), env=env,
                         capture_output=True, text=True, timeout=BLOCK_TIMEOUT)
    example.namespace["__timings__"].append((example.line, time.monotonic() - started))
    return res


def _failure(example, command: str, res: subprocess.CompletedProcess, why: str) -> str:
    tail = (res.stdout[-1500:] + "\n" + res.stderr[-2500:]).strip()
    return f"{why} (exit {res.returncode}):\n{command.strip()}\n--- output ---\n{tail}"


def evaluate_bash(example) -> str | None:
    """A bash block: one script that must exit 0."""
    script = str(example.parsed)
    res = _run_shell(example, script)
    if res.returncode != 0:
        return _failure(example, script, res, "the block failed")
    return None


def console_steps(text: str) -> list[tuple[str, str]]:
    """(command, expected output) of every ``$ `` line of a console block."""
    steps: list[tuple[str, list[str]]] = []
    for line in text.splitlines():
        if line.startswith("$ "):
            steps.append((line[2:], []))
        elif steps:
            steps[-1][1].append(line)
        elif line.strip():
            raise ValueError(f"console block: output before the first '$ ' line: {line!r}")
    return [(cmd, "\n".join(out).strip() + "\n") for cmd, out in steps]


def evaluate_console(example) -> str | None:
    """A console block: every command exits 0 and prints what the page shows."""
    checker = doctest.OutputChecker()
    for command, expected in console_steps(str(example.parsed)):
        res = _run_shell(example, command)
        if res.returncode != 0:
            return _failure(example, command, res, "the command failed")
        got = res.stdout.strip() + "\n"
        if expected.strip() and not checker.check_output(expected, got, DOCTEST_FLAGS):
            return (f"`{command}` printed\n{got}which differs from the page's\n{expected}")
    return None


class PyconParser(PythonCodeBlockParser):
    """``pycon`` fences: doctests, as Python fences holding ``>>>`` are."""

    def __init__(self):
        super().__init__(doctest_optionflags=DOCTEST_FLAGS)
        self.codeblock_parser = CodeBlockParser("pycon", PythonEvaluator())


DOCS = Sybil(parsers=[SkipParser(), CodeBlockParser("bash", evaluate_bash),
                      CodeBlockParser("console", evaluate_console),
                      PythonCodeBlockParser(doctest_optionflags=DOCTEST_FLAGS), PyconParser()])


def _needs_slurm(example) -> bool:
    return (example.region.evaluator in (evaluate_bash, evaluate_console)
            and "sbatch" in str(example.parsed))


def checkout_folder(path: Path) -> Path:
    """A fresh folder holding what a checkout holds next to the commands."""
    for name in COPIED:
        shutil.copytree(ROOT / name, path / name, ignore=NOT_COPIED, symlinks=True)
    (path / "benchmarks" / "results").mkdir(exist_ok=True)
    (path / ".venv").symlink_to(Path(sys.prefix))
    os.chmod(path, 0o755)  # SLURM jobs run from here
    return path


# ---- the tests ----------------------------------------------------------------------


@pytest.mark.slow  # every command of every page
@pytest.mark.parametrize("page", pages(), ids=page_id)
def test_page_commands_run_as_written(page, tmp_path_factory, monkeypatch, request):
    """The page's blocks, in order, in a fresh folder: each exits 0 and prints what it shows."""
    document = DOCS.parse(page)
    examples = list(document)
    folder = checkout_folder(tmp_path_factory.mktemp(page.stem))
    monkeypatch.chdir(folder)
    env, no_slurm = _shell_env(), None
    if any(_needs_slurm(e) for e in examples):
        try:
            env.update(request.getfixturevalue("slurm").env, PATH=env["PATH"])
        except pytest.skip.Exception as why:  # the other blocks still run
            no_slurm = str(why)
    document.namespace.update(__env__=env, __timings__=[])
    skipped, started = [], time.monotonic()
    cpu, own = cpu_seconds(resource.RUSAGE_CHILDREN), cpu_seconds(resource.RUSAGE_SELF)
    for example in examples:
        where = f"{page_id(page)}, block at line {example.line}"
        if no_slurm and _needs_slurm(example):
            skipped.append(f"line {example.line}: {no_slurm}")
            continue
        try:
            example.evaluate()
        except SkipTest as why:
            skipped.append(f"line {example.line}: {why}")
        except Exception as exc:  # noqa: BLE001 - name the page and the block
            pytest.fail(f"{where}: {exc}", pytrace=False)
    slow = sorted(document.namespace["__timings__"], key=lambda t: -t[1])[:3]
    sys.stderr.write(f"\n{page_id(page)}: {time.monotonic() - started:.1f} s wall, "
                     f"CPU {cpu_seconds(resource.RUSAGE_CHILDREN) - cpu:.1f} s in its commands + "
                     f"{cpu_seconds(resource.RUSAGE_SELF) - own:.1f} s in its Python blocks"
                     + "".join(f", line {line}: {t:.1f} s" for line, t in slow)
                     + "".join(f"\n  not run, {s}" for s in skipped))
    if no_slurm:
        pytest.skip(f"{page_id(page)}: its SLURM blocks did not run: {no_slurm}")


def code_blocks(page: Path):
    """(line, fence language or None for an indented block, first line) of every code block."""
    tokens = MarkdownIt("commonmark").parse(page.read_text())
    for tok in tokens:
        if tok.type in ("fence", "code_block"):
            first = tok.content.strip().splitlines()[0] if tok.content.strip() else ""
            language = tok.info.split()[0] if tok.type == "fence" and tok.info.strip() else None
            yield tok.map[0] + 1, (language if tok.type == "fence" else None), tok.type, first


@pytest.mark.parametrize("page", pages(), ids=page_id)
def test_every_command_is_in_a_block_that_runs(page):
    """No command hides in an indented block, a bare fence or a text fence."""
    wrong = []
    for line, language, kind, first in code_blocks(page):
        if kind == "code_block":
            wrong.append(f"line {line}: an indented code block (fence it: ```bash, ```text ...)")
        elif language is None:
            wrong.append(f"line {line}: a fence without a language")
        elif language not in RUN_LANGUAGES and COMMAND_START.match(first):
            wrong.append(f"line {line}: a command in a ```{language} fence, which is not run: "
                         f"{first!r}")
    assert not wrong, f"{page_id(page)}:\n" + "\n".join(wrong)


def test_console_blocks_parse():
    """The console reader splits commands from the outputs the page shows."""
    steps = console_steps("$ echo a\na\n$ true\n$ printf 'x\\ny'\nx\ny\n")
    assert steps == [("echo a", "a\n"), ("true", "\n"), ("printf 'x\\ny'", "x\ny\n")]
    with pytest.raises(ValueError, match="before the first"):
        console_steps("output\n$ true\n")
