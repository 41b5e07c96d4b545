"""postproc correct: correct NC programs with a calibration."""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import click

# build_setup: re-exported for the flags files of tests/cases
from postproc.cli.options import build_setup as build_setup
from postproc.cli.options import correction_options, limit_options, program_setup_options
from postproc.errors import PostprocError

# Files larger than this get a progress line on stderr (when stderr is a terminal).
PROGRESS_MIN_BYTES = 2_000_000


def load_maps(paths) -> list:
    if not paths:
        return []
    try:
        from postproc.mirror.maps import load_map
    except ImportError:
        raise PostprocError("--map needs the measured-map reader (postproc.mirror.maps), which is not "
                            "available in this installation") from None
    return [load_map(p) for p in paths]


def _summary(src: str, dst: str, rep, tolerance_mm: float) -> str:
    from postproc.gcode.options import GROWTH_WARN

    lines = [
        f"{src} -> {dst}: {rep.lines_in} lines, {rep.moves} moves, {rep.lines_changed} lines edited, "
        f"{rep.lines_inserted} lines inserted, arcs kept {rep.arcs_kept} / linearised "
        f"{rep.arcs_linearised}, largest correction {rep.max_correction_mm * 1000:.1f} um"
    ]
    lines.append(f"  growth {rep.lines_out - rep.header_lines:,} / {rep.lines_in:,} lines = {rep.growth:.2f}x "
                 f"(+{rep.header_lines} header lines); arcs split into exact arcs "
                 f"{rep.arcs_split}, reversal take-ups {rep.takeups}" + (
                     f"  (warning: over {GROWTH_WARN:g}x; a controller's program memory may not hold it)"
                     if rep.growth > GROWTH_WARN else ""))
    if rep.expanded:
        lines.append("  note: subprograms, loops, parameters and expressions were expanded: the corrected "
                     "program is flat (recorded in the header)")
    if rep.cutter is not None:
        from postproc.gcode.places import line_place

        cut = rep.cutter
        lines.append(f"  cutter radius compensation kept: {cut.moves} moves offset by the controller; the "
                     f"correction changes by at most {cut.bound_mm * 1000:.2f} um across the tool radius "
                     f"(line {line_place(cut.lineno, cut.path or src, src)}, {cut.source} radius "
                     f"{cut.radius_mm:g} mm)")
    if rep.cycles_kept or rep.cycles_expanded:
        lines.append(f"  canned cycles: {rep.cycles_kept} kept, {rep.cycles_expanded} expanded")
    if rep.g54_assumed_zero:
        lines.append("  note: no --offset G54 given: the program's coordinates were taken as machine coordinates "
                     "(G54 = 0); recorded in the header")
    if rep.extrapolated_points:
        lines.append(f"  note: {rep.extrapolated_points} points outside the calibrated volume were extrapolated")
    if rep.solver:
        lines.append(f"  solver {rep.solver}: largest inverse residual {rep.max_residual_mm * 1000:.3g} um "
                     f"(accepted up to {rep.accept_residual_mm * 1000:.4g} um)")
        if rep.max_residual_mm > tolerance_mm:
            lines.append(f"  note: the solver's residual exceeds --tolerance {tolerance_mm:g} mm: the corrected "
                         "targets are only as close to the nominal as that residual")
    return "\n".join(lines)


def _run_one(job: dict) -> tuple[str, str | None, int]:
    """Correct one file (runs in a worker process with -j); returns (summary, error, exit code)."""
    from postproc.calfile import load_calibration
    from postproc.fileio import as_regular_file
    from postproc.gcode.pipeline import CorrectOptions, correct_file
    from postproc.gcode.recognise import dialect_of_file

    try:
        cal = load_calibration(job["calibration"])
        opts = CorrectOptions(**job["options"], added=load_maps(job["maps"]))
        with as_regular_file(job["src"]) as src:  # (a pipe: read once into a file)
            _refuse_without_code(src, job["src"])
            opts.dialect = dialect_of_file(src, opts.dialect)  # generic: Sinumerik by its header
            rep = correct_file(src, job["dst"], cal.engine, job["setup"], opts,
                               calibration_name=cal.name, calibration_sha256=cal.sha256)
        return _summary(job["src"], job["dst"], rep, opts.tolerance_mm), None, 0
    except PostprocError as exc:
        return "", str(exc.with_column()), exc.exit_code
    except Exception as exc:  # a bug: name it for this file and go on with the others
        from postproc.errors import EXIT_INTERNAL

        return "", f"internal error: {type(exc).__name__}: {exc} (a bug in postproc: please report it)", EXIT_INTERNAL


# Files taken from a folder given as input: G-code suffixes, and no suffix (Fanuc and Haas
# programs are often named O1234).
PROGRAM_SUFFIXES = {"", ".nc", ".ngc", ".gcode", ".gc", ".g", ".tap", ".cnc", ".eia", ".mpf", ".min", ".ptp",
                    ".txt", ".iso", ".ncc", ".dnc", ".fnc", ".nci"}


def _expand_inputs(inputs) -> tuple[list[str], bool]:
    """Inputs with each folder replaced by its programs (files directly in it with a
    G-code suffix or none, hidden files left out, sorted); and whether a folder was given."""
    out: list[str] = []
    folder = False
    for src in inputs:
        p = Path(src)
        if src != "-" and p.is_dir():
            folder = True
            files = sorted(str(f) for f in p.iterdir()
                           if f.is_file() and not f.name.startswith(".") and f.suffix.lower() in PROGRAM_SUFFIXES)
            if not files:
                raise click.UsageError(f"folder {src} holds no program (files ending in .nc, .ngc, .tap, "
                                       "... or without an extension)")
            out.extend(files)
        else:
            out.append(src)
    return out, folder


def _cores() -> int:
    """The cores this process may run on."""
    affinity = getattr(os, "sched_getaffinity", None)  # Linux
    return len(affinity(0)) if affinity is not None else (os.cpu_count() or 1)


def _progress_printer(total_hint: str):
    def show(n: int) -> None:
        click.echo(f"\r{total_hint}: {n:,} lines", nl=False, err=True)
    return show


@click.command()
@click.argument("inputs", nargs=-1, required=True, metavar="IN...")
@click.option("-c", "--calibration", required=True, type=click.Path(dir_okay=False),
              help="Calibration file (from 'postproc fit').")
@click.option("-o", "--output", default=None,
              help="Output program ('-' for stdout). One input only. A symbolic link is written through; "
                   "a device such as /dev/null is written, never replaced.")
@click.option("--output-dir", default=None, type=click.Path(file_okay=False),
              help="Directory for the corrected programs (same names); for several inputs or a folder.")
@click.option("-j", "--jobs", default=None, type=click.IntRange(1, 256),
              help="Processes. Several inputs or a folder: this many files at a time [default: 1], ending "
                   "with a tally of corrected and refused files. One large program (from 40,000 lines; "
                   "16,000 when the calibration's moves are sampled): cut into parts corrected in up to "
                   "this many processes "
                   "[default: one per core], with the output of one process; -j 1 keeps it in one.")
@program_setup_options
@correction_options
@limit_options
@click.option("--map", "maps", multiple=True, type=click.Path(dir_okay=False),
              help="Measured correction map added after the calibration's correction. Repeatable.")
def correct(inputs, calibration, output, output_dir, jobs, reading, setup, correcting, maps, limits):
    """Correct NC programs for the machine's measured errors.

    Each move's target is sent through the calibration's inverse model and the
    coordinate words that change are rewritten; every other byte is kept. Moves
    along which the correction varies are split, and arcs that would leave the
    tolerance are turned into lines. Nothing is written when a safety rule refuses
    the job (correction too large, target outside the calibrated volume, work
    offset or tool length not given, program already corrected).

    A program that never names a work offset runs in G54; without --offset G54
    its coordinates are taken as machine coordinates (noted in the header).

    An axis the program never positions (Z in 2-D engraving files) stays where
    the machine is: give that machine position with --start (and the work
    offset with --offset G54=...); the corrected program then names that axis
    wherever the correction moves it.

    The corrected program opens with a few short (POSTPROC ...) comment lines
    (after a % line and an O number line) that the --dialect's controller
    reads: version, calibration and its sha256, tolerance and the setup. An
    empty program is refused.

    A folder as input corrects every program in it (files ending in .nc, .ngc,
    .tap, ... or without an extension) into --output-dir, -j at a time, with a
    line per file and a tally at the end; the exit code is non-zero when any
    file was refused. IN may be - (standard input) or a pipe such as a shell's
    <(...): it is read once into a temporary file.

    Example:

    \b
        postproc correct samples/pocket.nc -c calibrations/s500_static.json -o pocket_corrected.nc
        postproc correct programs/ -c calibrations/s500_static.json --output-dir corrected/ -j 4
        postproc correct samples/g54_g43.ngc -c calibrations/s500_static.json \\
            --offset G54=X100,Y80,Z40 --tool-length 1=100 -o part_corrected.ngc
        postproc correct engraving.tap -c calibrations/s500_static.json \\
            --offset G54=X100,Y100,Z0 --start Z150 -o engraving_corrected.tap
        postproc correct samples/fanuc_drill.nc -c calibrations/s500_static.json \\
            --offset G54=X100,Y100,Z-200 --tool-length 1=100 --home G28=X0,Y0,Z0 -o drill_corrected.nc
    """
    inputs, folder = _expand_inputs(inputs)
    if folder and output is not None:
        raise click.UsageError("a folder as input needs --output-dir, not -o")
    if folder and output_dir is None:
        raise click.UsageError("a folder as input needs --output-dir for the corrected programs")
    if len(inputs) > 1 and output is not None:
        raise click.UsageError("-o takes one input; use --output-dir for several")
    if output is not None and output_dir is not None:
        raise click.UsageError("give -o or --output-dir, not both")
    if "-" in inputs and len(inputs) > 1:
        raise click.UsageError("'-' (stdin) can only be the only input")
    options = {**correcting, **reading.correct_options(), "limits": limits}
    if len(inputs) == 1 and not folder and (output is not None or output_dir is None):
        processes = jobs if jobs is not None else _cores()
        _single(inputs[0], output or "-", calibration, setup, {**options, "processes": processes}, maps)
        return
    if output_dir is None:
        raise click.UsageError("several inputs need --output-dir")
    names = [Path(src).name for src in inputs]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise click.UsageError(f"several inputs are named {', '.join(dupes)}: their outputs would collide in --output-dir")
    out_dir = Path(output_dir)
    if out_dir.is_dir() and any(Path(src).parent.resolve() == out_dir.resolve() for src in inputs if src != "-"):
        raise click.UsageError(f"--output-dir {output_dir} is the folder of the inputs: the corrected programs "
                               "would replace them; give another folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    jobs_list = []
    for src in inputs:
        dst = str(out_dir / Path(src).name)
        _check_not_same(src, dst)
        jobs_list.append({"src": src, "dst": dst, "calibration": calibration, "setup": setup,
                          "options": options, "maps": list(maps)})
    _batch(jobs_list, jobs or 1)


def _batch(jobs_list: list[dict], jobs: int) -> None:
    """Correct every job, one stderr line per file as it ends, then the tally; exit with
    the worst refusal's code when any file was refused."""
    total = len(jobs_list)
    results: list = [None] * total
    width = len(str(total))

    def placed(src: str, error: str) -> str:
        """The error with its file named once (most errors begin with the file's place)."""
        return error if error.startswith(f"{src}:") else f"{src}: {error}"

    def report(k: int, done: int, res) -> None:
        summary, error, _code = res
        src = jobs_list[k]["src"]
        if error:
            click.echo(f"[{done:>{width}}/{total}] refused   {placed(src, error).splitlines()[0]}", err=True)
        else:
            click.echo(f"[{done:>{width}}/{total}] corrected {summary}", err=True)

    if jobs > 1 and total > 1:
        from concurrent.futures import as_completed

        from postproc.cli.signals import run_guarded, worker_init

        pool = ProcessPoolExecutor(max_workers=min(jobs, total), initializer=worker_init)
        try:
            futures = {pool.submit(run_guarded, _run_one, j): k for k, j in enumerate(jobs_list)}
            for done, fut in enumerate(as_completed(futures), start=1):
                k = futures[fut]
                results[k] = fut.result()
                report(k, done, results[k])
        except KeyboardInterrupt:
            # stopped by a signal: each worker removes its temporary output and ends
            # (postproc.cli.signals.run_guarded), the files not started are not
            for process in list(getattr(pool, "_processes", {}).values()):
                if process.is_alive():
                    process.terminate()
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        pool.shutdown()
    else:
        for k, j in enumerate(jobs_list):
            results[k] = _run_one(j)
            report(k, k + 1, results[k])
    refused = [(jobs_list[k]["src"], r) for k, r in enumerate(results) if r[1]]
    click.echo(f"{total} file{'s' if total != 1 else ''}: {total - len(refused)} corrected, "
               f"{len(refused)} refused", err=True)
    for src, (_summary, error, code) in refused:
        first, *rest = placed(src, error).splitlines()
        click.echo("\n".join([f"  refused (exit {code}) {first}", *(f"  {r}" for r in rest)]), err=True)
    if refused:
        sys.exit(max(code for _src, (_s, _e, code) in refused))


def _refuse_without_code(path: str, shown: str) -> None:
    """Refuse (exit 3, nothing written) a program of comments, ``%`` lines and blanks only:
    there is nothing to correct, and a batch that gets one was most often handed the wrong
    file, or a CAM post that failed after writing its header. ``shown``: the name to give."""
    from postproc.fileio import read_lines
    from postproc.gcode.expand_syntax import holds_no_code
    from postproc.gcode.path import open_source

    with open_source(path) as fh:
        if holds_no_code(read_lines(fh, shown)):
            raise PostprocError("the program holds only comments and '%' lines, no G-code: nothing to correct",
                                path=shown, hint="check that this is the program you meant (was it written "
                                "completely? a CAM post that failed may write only its header comments)")


def _check_not_same(src: str, dst: str) -> None:
    if src != "-" and dst != "-" and Path(dst).exists() and Path(src).resolve() == Path(dst).resolve():
        raise click.UsageError(f"output {dst} is the input itself; write the corrected program elsewhere")


def _single(src: str, dst: str, calibration: str, setup, options: dict, maps) -> None:
    from postproc.calfile import load_calibration
    from postproc.fileio import as_regular_file
    from postproc.gcode.pipeline import CorrectOptions, correct_file
    from postproc.gcode.recognise import dialect_of_file

    _check_not_same(src, dst)
    cal = load_calibration(calibration)
    opts = CorrectOptions(**options, added=load_maps(maps))
    progress = None
    if src != "-" and sys.stderr.isatty() and os.path.getsize(src) > PROGRESS_MIN_BYTES:
        progress = _progress_printer(src)
    shown = "<stdin>" if src == "-" else src
    tmpdir = None
    try:
        # a pipe or standard input is read once into a file: the program is read more than once
        with as_regular_file(src) as src_path:
            _refuse_without_code(src_path, shown)
            opts.dialect = dialect_of_file(src_path, opts.dialect)  # generic: Sinumerik by its header
            if dst == "-":
                tmpdir = tempfile.mkdtemp(prefix="postproc-")
                out_path = os.path.join(tmpdir, "out.nc")
            else:
                out_path = dst
            rep = correct_file(src_path, out_path, cal.engine, setup, opts,
                               calibration_name=cal.name, calibration_sha256=cal.sha256, progress=progress)
        if progress is not None:
            click.echo("", err=True)
        if dst == "-":
            with open(out_path, "rb") as fh:
                out = sys.stdout.buffer if hasattr(sys.stdout, "buffer") else None
                if out is None:
                    sys.stdout.write(fh.read().decode("utf-8", errors="surrogateescape"))
                else:
                    shutil.copyfileobj(fh, out)
                    out.flush()
    finally:
        if tmpdir:
            shutil.rmtree(tmpdir, ignore_errors=True)
    click.echo(_summary(shown, "<stdout>" if dst == "-" else dst, rep, opts.tolerance_mm),
               err=True)

