"""A program given as a pipe (a shell's ``<(...)``, a named FIFO) is read once into a
file: correct, diff and verify read a program more than once, and a pipe gives its
bytes only to the first reading (diff reported "0 moves" and correct "the program is
empty" or waited forever for a writer)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading

import pytest
from click.testing import CliRunner

from postproc.cli import main
from postproc.errors import PostprocError
from postproc.fileio import as_regular_file
from tests.conftest import ROOT

POCKET = ROOT / "samples" / "pocket.nc"
STATIC = ROOT / "calibrations" / "s500_static.json"
MACHINE = ROOT / "calibrations" / "s500.machine.json"

pytestmark = pytest.mark.skipif(not os.path.exists("/dev/fd"), reason="/dev/fd names a pipe's end (Linux)")


def pipe_of(data: bytes) -> str:
    """A pipe holding ``data`` (written and closed), named as a shell's ``<(...)`` names it."""
    r, w = os.pipe()
    assert len(data) < 65536  # (what a pipe holds unread)
    os.write(w, data)
    os.close(w)
    return f"/dev/fd/{r}"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_a_regular_file_is_read_where_it_is(tmp_path):
    with as_regular_file(str(POCKET)) as path:
        assert path == str(POCKET)


def test_a_pipe_is_read_once_into_a_file_removed_after():
    data = POCKET.read_bytes()
    with as_regular_file(pipe_of(data)) as path:
        assert os.path.isfile(path)
        with open(path, "rb") as fh:
            assert fh.read() == data
        with open(path, "rb") as fh:  # and again
            assert fh.read() == data
    assert not os.path.exists(path)


def test_an_error_in_the_copy_names_the_pipe_with_its_column():
    pipe = pipe_of(b"G21\n   G1 X5 Q\n")
    with pytest.raises(PostprocError) as err, as_regular_file(pipe) as path:
        raise PostprocError("something on line 2", path=path, lineno=2)
    assert err.value.path == pipe
    assert err.value.col == 4  # read from the copy before it went


def test_correct_from_a_pipe_writes_what_the_file_gives(tmp_path):
    one = run("correct", POCKET, "-c", STATIC, "-o", tmp_path / "file.nc")
    two = run("correct", pipe_of(POCKET.read_bytes()), "-c", STATIC, "-o", tmp_path / "pipe.nc")
    assert one.exit_code == 0, one.output
    assert two.exit_code == 0, two.output
    assert (tmp_path / "pipe.nc").read_bytes() == (tmp_path / "file.nc").read_bytes()


def test_correct_names_the_pipe_where_its_program_is_refused(tmp_path):
    res = run("correct", pipe_of(b"G21 G90\nG0 X10 Y10 Z5\nG1 X20 Y10 G99.5 F100\nM2\n"), "-c", STATIC,
              "-o", tmp_path / "out.nc")
    assert res.exit_code == 3
    assert ":3:12: G99.5" in res.output
    assert "/dev/fd/" in res.output
    assert not (tmp_path / "out.nc").exists()


def test_correct_from_a_named_pipe_does_not_wait_for_a_second_writer(tmp_path):
    fifo = tmp_path / "program.nc"
    os.mkfifo(fifo)
    writer = threading.Thread(target=lambda: fifo.write_bytes(POCKET.read_bytes()), daemon=True)
    writer.start()
    out = tmp_path / "out.nc"
    proc = subprocess.run([sys.executable, "-m", "postproc", "correct", str(fifo), "-c", str(STATIC), "-o", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    writer.join(5)
    assert proc.returncode == 0, proc.stderr
    assert run("correct", POCKET, "-c", STATIC, "-o", tmp_path / "file.nc").exit_code == 0
    assert out.read_bytes() == (tmp_path / "file.nc").read_bytes()


def test_diff_of_two_pipes_reports_what_the_files_give(tmp_path):
    corrected = tmp_path / "corrected.nc"
    assert run("correct", POCKET, "-c", STATIC, "-o", corrected).exit_code == 0
    files = run("diff", POCKET, corrected, "--json")
    pipes = run("diff", pipe_of(POCKET.read_bytes()), pipe_of(corrected.read_bytes()), "--json")
    assert files.exit_code == 0, files.output
    assert pipes.exit_code == 0, pipes.output
    a, b = json.loads(files.output), json.loads(pipes.output)
    assert b["moves"] == a["moves"] > 0
    assert b["original"].startswith("/dev/fd/")
    assert {k: v for k, v in b.items() if k not in ("original", "corrected")} == \
           {k: v for k, v in a.items() if k not in ("original", "corrected")}


def test_verify_a_program_from_a_pipe(tmp_path):
    files = run("verify", POCKET, "-c", STATIC, "--machine", MACHINE, "--json")
    pipes = run("verify", pipe_of(POCKET.read_bytes()), "-c", STATIC, "--machine", MACHINE, "--json")
    assert files.exit_code == 0, files.output
    assert pipes.exit_code == 0, pipes.output
    assert json.loads(pipes.output)["runs"] == json.loads(files.output)["runs"]
