"""``python -m sliders.merge OUT IN...``: join ensemble chunk files into one ensemble file.

An ensemble of R realisations can be cut into K chunks run independently
(a SLURM job array: ``python -m sliders.ensemble --realisations R --chunk I/K``).
Realisation r always has the seed ``realisation_seed(scene seed, r)``, so
chunk I holds exactly the rows I*R//K .. (I+1)*R//K - 1 that one run over
all R realisations would hold, and the merged file has the same rows as that
one run, bit for bit (apart from the wall times).

The inputs must hold the same scene, backend and statistics grids, and their
realisation ranges must tile 0..R-1 without overlap (in any order on the
command line).  Rows a chunk has not completed (an interrupted task) stay
not done; ``python -m sliders.ensemble --resume`` on the merged file
computes them.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile

import numpy as np

from ..analysis.observables import StatisticsGrids, statistic_conventions, statistics_layout
from .command import error_line
from .rows import realisation_seeds
from .signals import stop_signal, stopped_by_sigterm
from ..io import safeio
from ..io.conventions import describe_ensemble_file
from ..io.filelock import ClaimError, OutputClaim
from ..io.safeio import (check_output_name, describe_os_error, is_special, leftovers_note,
                         resolve_target)
from ..io.storage import (GatherFile, StorageError, check_space, file_attributes, make_layout,
                          read_header, read_rows)
from ..scene import Scene


class MergeError(Exception):
    """Inputs that do not form one ensemble (one line to the user)."""


def parse_chunk(text: str) -> tuple[int, int]:
    """``"I/K"`` -> ``(I, K)`` with 0 <= I < K (an argparse type)."""
    try:
        i, k = (int(part) for part in str(text).split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not I/K (two integers, e.g. 3/8)") from None
    if k < 1 or not 0 <= i < k:
        raise argparse.ArgumentTypeError(f"chunk {text!r} needs 0 <= I < K")
    return i, k


def chunk_range(chunk: tuple[int, int], n_realisations: int) -> tuple[int, int]:
    """``(first, count)`` of chunk ``(I, K)`` of ``n_realisations``: rows I*R//K .. (I+1)*R//K - 1."""
    i, k = chunk
    if k > n_realisations:
        raise ValueError(f"--chunk {i}/{k}: {k} chunks of {n_realisations} realisations would "
                         "leave some empty; use K <= R")
    first = i * n_realisations // k
    return first, (i + 1) * n_realisations // k - first


def _describe(path: str, head: dict) -> str:
    first = int(head["attrs"].get("first_realisation", 0))
    return f"{path} (realisations {first}..{first + int(head['attrs']['realisations']) - 1})"


def merge(out, inputs, overwrite: bool = False, notes=None) -> dict:
    """Write the ensemble made of the chunk files ``inputs`` to ``out``; returns counts.

    On the ensemble's footing: ``out`` is checked (name, folder) and claimed
    (``OutputClaim``: refused while an ensemble or another merge writes it)
    before anything is read; an output that is one of the inputs (the same
    file, by device and inode or real path, whatever the path typed) or that
    is not a regular file is refused; the merged file is built under a
    temporary name beside ``out`` and renamed over it once complete, so that
    an existing ``out`` stays as it was until then (an interruption or a full
    disk leaves it untouched, and no temporary file).  ``notes``: a list that
    receives lines for the user (temporary files of an earlier, killed merge
    that were removed).
    """
    out = os.fspath(out)
    if not inputs:
        raise MergeError("no input files")
    try:
        check_output_name(out)
    except ValueError as exc:
        raise MergeError(str(exc)) from None
    target = resolve_target(out)
    if os.path.isdir(target.real):
        raise MergeError(f"{out!r} is a directory; give the merged file's path")
    if target.identity is not None and not os.path.isfile(target.real):
        raise MergeError(f"{out!r} is not a regular file (a device, a fifo or a socket); the "
                         "merged ensemble must be a file")
    if target.identity is not None and not overwrite:
        raise MergeError(f"{out!r} exists; pass --overwrite to replace it")
    for p in map(os.fspath, inputs):
        if resolve_target(p).same_file(target):
            raise MergeError(f"{p!r} is both an input and the output {out!r} (the same file); "
                             "write the merged ensemble elsewhere")
    _check_folder(out, target.real)
    try:
        claim = OutputClaim(out).acquire()
    except ClaimError as exc:
        raise MergeError(str(exc)) from None
    try:
        if not claim.locking and target.identity is not None:
            raise MergeError(f"{out!r}: this file system does not support file locks, so a "
                             "concurrent writer could not be detected; --overwrite is refused "
                             "there (delete the file first, or write elsewhere)")
        if claim.leftovers and notes is not None:
            notes.append(leftovers_note(claim.leftovers))
        if is_special(target.real):  # appeared meanwhile
            raise MergeError(f"{out!r} is not a regular file")
        return _merge_claimed(out, list(map(os.fspath, inputs)), overwrite)
    finally:
        claim.release()


def _check_folder(out: str, real: str) -> None:
    """The folder of ``out`` exists and takes a new file (probed, as for an ensemble)."""
    folder = os.path.dirname(real) or "."
    if not os.path.isdir(folder):
        raise MergeError(f"{out!r}: directory {folder!r} does not exist")
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        raise MergeError(f"cannot create files beside {out!r}: "
                         f"{describe_os_error(exc, folder)}") from None


def _read_chunks(inputs: list[str]) -> list[tuple[str, dict]]:
    """The headers of the chunk files, in realisation order, checked to be chunks of one
    ensemble that cover realisations 0..R-1 once each."""
    heads = []
    for p in inputs:
        try:
            heads.append((p, read_header(p)))
        except StorageError as exc:
            raise MergeError(str(exc)) from None
    heads.sort(key=lambda ph: int(ph[1]["attrs"].get("first_realisation", 0)))
    p0, h0 = heads[0]
    for key in ("scene", "backend", "format_version"):
        for p, h in heads[1:]:
            if h["attrs"].get(key) != h0["attrs"].get(key):
                raise MergeError(f"{p!r} and {p0!r} differ in {key} ({h['attrs'].get(key)!r} vs "
                                 f"{h0['attrs'].get(key)!r}); they are not chunks of one ensemble")
    for p, h in heads[1:]:
        for k, v in h0["grids"].items():
            if k not in h["grids"] or not np.array_equal(h["grids"][k], v):
                raise MergeError(f"{p!r} and {p0!r} differ in the statistics grid {k!r}")
    expected = 0
    for (p, h), prev in zip(heads, [None] + heads[:-1]):
        first = int(h["attrs"].get("first_realisation", 0))
        if first < expected:
            raise MergeError(f"{_describe(p, h)} overlaps {_describe(*prev)}")
        if first > expected:
            raise MergeError(f"realisations {expected}..{first - 1} are in no input file "
                             f"(the next one is {_describe(p, h)})")
        expected = first + int(h["attrs"]["realisations"])
    return heads


def _merged_layout(heads: list[tuple[str, dict]]):
    """The layout of the whole ensemble the chunks belong to; every chunk's columns and seeds
    checked against it."""
    h0 = heads[0][1]
    last = heads[-1][1]["attrs"]
    n_total = int(last.get("first_realisation", 0)) + int(last["realisations"])
    scene = Scene.from_stored(json.loads(h0["attrs"]["scene"]))
    grids = StatisticsGrids.from_arrays(h0["grids"])
    seeds = realisation_seeds(scene.seed, 0, n_total)
    attrs = file_attributes(scene.to_dict(), scene.seed, n_total, str(h0["attrs"]["backend"]))
    attrs["first_realisation"] = 0
    layout = make_layout(n_total, seeds, h0["grids"],
                         statistics_layout(grids, scene.n_sliders)
                         if any(k.startswith("statistics/") for k in h0["columns"]) else {},
                         attrs)
    names = [c.name for c in layout.columns]
    for p, h in heads:
        missing = [n for n in names if n not in h["columns"]]
        if missing:
            raise MergeError(f"{p!r} lacks the column(s) {missing}")
        first = int(h["attrs"].get("first_realisation", 0))
        if not np.array_equal(h["seeds"], seeds[first:first + h["seeds"].size]):
            raise MergeError(f"{p!r} holds other seeds than realisations "
                             f"{first}..{first + h['seeds'].size - 1} of this scene")
    return layout


def _write_merged(tmp: str, heads, layout, out: str) -> int:
    """Build the merged file ``out`` at ``tmp`` (rows done in the chunks, then the description);
    the number of rows done."""
    names = [c.name for c in layout.columns]
    handler = GatherFile.build(tmp, layout)
    n_done = 0
    try:
        for p, h in heads:
            first = int(h["attrs"].get("first_realisation", 0))
            rows = read_rows(p)
            for i in np.flatnonzero(h["done"]):
                handler.write_row(first + int(i), {n: rows[n][i] for n in names})
                handler.mark_done(first + int(i))
                n_done += 1
        handler.flush()
    finally:
        handler.close()
    # the chunks' commands first; describe adds this merge
    history = "\n".join(str(h["attrs"]["history"]) for _, h in heads if h["attrs"].get("history"))
    described = describe_ensemble_file(tmp, statistic_conventions(), history)
    if described is not True:
        raise MergeError(f"cannot write {out!r}: {described}")
    return n_done


def _merge_claimed(out: str, inputs: list[str], overwrite: bool) -> dict:
    """``merge`` once ``out`` is checked and claimed: read, build beside, publish by rename."""
    heads = _read_chunks(inputs)
    layout = _merged_layout(heads)
    try:
        check_space(out, layout)
    except StorageError as exc:
        raise MergeError(f"cannot write {out!r}: {exc}") from None
    except OSError as exc:
        raise MergeError(f"cannot write {safeio.describe_os_error(exc, out)}") from None
    tmp = None
    try:
        tmp = safeio.temporary_beside(out)
        n_done = _write_merged(tmp, heads, layout, out)
        safeio.fsync_path(tmp)
        safeio.publish(tmp, out, overwrite=True)  # the old file stays until this rename
    except StorageError as exc:
        raise MergeError(str(exc)) from None
    except OSError as exc:
        raise MergeError(f"cannot write {safeio.describe_os_error(exc, out)}; "
                         f"{'the existing file is unchanged' if overwrite else 'nothing written'}") \
            from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
    return {"realisations": layout.n_realisations, "done": n_done, "inputs": len(heads)}


class _Parser(argparse.ArgumentParser):
    """argparse that reports a bad option in one line (no usage block)."""

    def error(self, message):
        """Print one line and exit with status 2 (not argparse's usage block)."""
        sys.stderr.write(f"error: {message} (see --help)\n")
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``python -m sliders.merge``."""
    p = _Parser(
        prog="python -m sliders.merge",
        description="Join ensemble chunk files (python -m sliders.ensemble --chunk I/K) into one "
                    "ensemble file with the same rows as one run over all realisations.")
    p.add_argument("out", metavar="OUT.h5", help="merged ensemble file")
    p.add_argument("inputs", metavar="IN.h5", nargs="+", help="chunk files, in any order")
    p.add_argument("--overwrite", action="store_true", help="replace an existing OUT.h5")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run ``python -m sliders.merge`` (join the chunk files of one ensemble); returns the exit code."""
    args = build_parser().parse_args(argv)
    notes: list[str] = []

    try:
        with stopped_by_sigterm():  # a batch system's stop: as Ctrl-C, cleanly
            counts = merge(args.out, args.inputs, overwrite=args.overwrite, notes=notes)
    except (MergeError, OSError, ValueError, RuntimeError) as exc:
        for note in notes:
            sys.stderr.write(f"merge: note: {note}\n")
        sys.stderr.write(error_line(str(exc)) + "\n")
        return 1
    except KeyboardInterrupt as exc:
        sys.stderr.write(f"merge: interrupted; {args.out} is unchanged and no temporary file is "
                         "left\n")
        return 128 + stop_signal(exc)
    for note in notes:
        sys.stderr.write(f"merge: note: {note}\n")
    sys.stderr.write(f"merge: {counts['inputs']} files, {counts['done']}/{counts['realisations']} "
                     f"realisations done -> {args.out}\n")
    if counts["done"] < counts["realisations"]:
        sys.stderr.write(f"merge: warning: {counts['realisations'] - counts['done']} realisation(s) "
                         "not done; complete them with python -m sliders.ensemble --resume "
                         f"--out {args.out} (same scene options)\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
