"""Real programs that use parameters, O-words or subprograms, expanded and run by rs274.

Every program of ``../shared/corpus/real`` and ``../shared/corpus/linuxcnc`` that
:func:`needs_expansion` is expanded; when LinuxCNC's interpreter accepts the program
as written, it must accept the expansion and move identically. When it refuses the
program, the expansion must either refuse it too with a placed error or give a
program that rs274 refuses as well: never a traceback.

Subroutine files are found the way the programs expect them: the LinuxCNC shop
programs call ``o<name>`` subroutines kept as ``nc_files__<name>.ngc``, the Fanuc
sample calls ``M98 P5001`` kept as ``...Fanuc__5001.nc``; both are put under their
own names in a temporary subroutine directory. The simulator's header comments with
nested parentheses, which LinuxCNC refuses, are removed from both runs.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from conftest import FULL_CORPUS, representative
from oracle import requires_rs274, run_rs274, same_motions

from postproc.errors import PostprocError
from postproc.gcode.expand import expand, needs_expansion
from postproc.gcode.lexer import split_lines

CORPUS = Path(__file__).resolve().parents[2] / "shared" / "corpus"
# rs274 and the expansion take ~5 s on the largest corpus programs; beyond this size
# a program is left to the benchmarks.
MAX_BYTES = 300_000
_NESTED_COMMENT_LINE = re.compile(r"^\([^)\n]*\([^\n]*\)[^\n]*\)[ \t]*\r?\n", re.MULTILINE)


def _read(path: Path) -> str:
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.lstrip("\ufeff")


def _is_subroutine_file(f: Path) -> bool:
    """A file the corpus' programs call (run through their callers instead)."""
    lagun = f.parent.name == "lagun_linuxcnc" and "__" not in f.name.removeprefix("nc_files__")
    fanuc = f.parent.name == "fanuc_sim" and re.search(r"Fanuc__\d+\.nc$", f.name) is not None
    return lagun or fanuc


def _programs() -> list[Path]:
    if not CORPUS.is_dir():
        return []
    files = sorted((CORPUS / "real").glob("*/*")) + sorted((CORPUS / "linuxcnc").glob("*"))
    out = []
    for f in files:
        if f.suffix == ".csv" or f.stat().st_size > MAX_BYTES or _is_subroutine_file(f):
            continue
        if needs_expansion(split_lines(_read(f))):
            out.append(f)
    return out


PROGRAMS = _programs()
# every one with POSTPROC_FULL_CORPUS=1, else a subset naming every construct, source and
# suffix they name (conftest.representative)
RUN = PROGRAMS if FULL_CORPUS else representative(PROGRAMS)


@pytest.fixture(scope="module")
def subroutines(tmp_path_factory):
    """(directory for expand, files for rs274) holding the corpus' subroutines by name."""
    d = tmp_path_factory.mktemp("subs")
    rs_files: dict[str, str] = {}
    for f in (CORPUS / "real" / "lagun_linuxcnc").glob("nc_files__*.ngc"):
        name = f.name.removeprefix("nc_files__")
        if "__" not in name:
            (d / name).write_text(_read(f))
            rs_files[name] = _read(f)
    for f in (CORPUS / "real" / "fanuc_sim").glob("*Fanuc__[0-9]*.nc"):
        number = re.search(r"__(\d+)\.nc$", f.name).group(1)
        (d / f"{number}.nc").write_text(_read(f))
        rs_files[f"{number}.ngc"] = f"O{number}\n" + _NESTED_COMMENT_LINE.sub("", _read(f))
    return d, rs_files


@pytest.mark.skipif(not CORPUS.is_dir(), reason="../shared/corpus is absent")
def test_corpus_has_programs_to_expand():
    names = {p.name for p in PROGRAMS}
    assert len(PROGRAMS) >= 30
    assert "mmount.ngc" in names  # LinuxCNC example with O-word subroutines
    assert any("M98_P" in n for n in names)  # Fanuc sample with M98 subprograms


@requires_rs274
@pytest.mark.skipif(not CORPUS.is_dir(), reason="../shared/corpus is absent")
@pytest.mark.parametrize("path", RUN, ids=[p.name[-40:] for p in RUN])
def test_corpus_program_expands_like_linuxcnc(path, subroutines):
    sub_dir, rs_files = subroutines
    text = _read(path)
    refused: PostprocError | None = None
    out = ""
    try:
        out = "".join(sl.text for sl in expand(split_lines(text), path=str(path), subroutine_path=[sub_dir]))
    except PostprocError as err:
        refused = err
    if refused is not None:
        assert refused.lineno is not None, str(refused)
        assert str(refused).startswith(refused.path), str(refused)
        ref = _reference(text, rs_files)
        assert not ref.ok or "not supported" in str(refused), f"rs274 runs it, the expansion refuses: {refused}"
        return
    ref = _reference(text, rs_files)
    got = run_rs274(_NESTED_COMMENT_LINE.sub("", out))  # flat: needs no subroutine file
    if not ref.ok:
        assert not got.ok, "rs274 refuses the program but runs its expansion"
        # the same refusal (e.g. no M2 at the end; rs274 words it shorter for an empty
        # program): the motions up to it must agree
        first_ref, first_got = ref.error.splitlines()[0], got.error.splitlines()[0]
        assert first_ref.startswith(first_got) or first_got.startswith(first_ref)
        assert same_motions(ref.motions, got.motions) == ""
        return
    assert got.ok, got.error
    assert same_motions(ref.motions, got.motions) == ""


def _reference(text: str, rs_files: dict[str, str]):
    calls = re.search(r"call|m\s*98", text, re.IGNORECASE) is not None
    return run_rs274(_NESTED_COMMENT_LINE.sub("", text), files=rs_files if calls else None)
