"""SIGINT, SIGTERM and SIGHUP stop a command with its cleanup: no temporary file beside
the output, none in the temporary folder (the copy of a piped program), no child process
left, exit 128 + n (130, 143, 129), one line on stderr and no traceback. Each run in a
subprocess, as a batch service would stop it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STATIC = str(ROOT / "calibrations" / "s500_static.json")
GENCAM = ROOT.parent / "shared" / "bench" / "gencam.py"  # ../shared, as every test finds it
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]


def _program(path: Path, lines: int) -> Path:
    """A CAM-like program of ``lines`` lines (gencam.py when there, else a zig-zag)."""
    if GENCAM.exists():
        subprocess.run([sys.executable, str(GENCAM), str(lines), str(path)], check=True, capture_output=True)
    else:
        body = [f"G1 X{10 + (i % 200):.3f} Y{10 + (i // 200) % 200 * 0.5:.3f} Z{5 + (i % 7) * 0.1:.3f}"
                for i in range(lines)]
        path.write_text("G90 G21 G54\nG0 X10 Y10 Z20\nF1500\n" + "\n".join(body) + "\nM2\n")
    return path


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    # long enough that every run is still correcting when its signal comes, on a machine
    # that corrects 250,000 lines a second in two processes (about 2 s of work)
    return _program(tmp_path_factory.mktemp("prog") / "big.nc", 500_000)


def _setup(tmp_path: Path) -> list[str]:
    table = tmp_path / "tools.tbl"
    table.write_text("".join(f"T{i} P{i} Z100\n" for i in range(1, 31)))
    return ["--offset", "G54=X0,Y0,Z50", "--tool-table", str(table)]


def _env(tmp: Path) -> dict:
    env = dict(os.environ, TMPDIR=str(tmp), PYTHONPATH=str(ROOT))
    env.pop("POSTPROC_DEBUG", None)
    return env


def _wait_for(predicate, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError("the run never reached the point to stop it at")


def _children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (Linux /proc)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d.name))
    return out


def _stop(proc: subprocess.Popen, sig: int, tmp: Path) -> str:
    kids = _children(proc.pid)
    proc.send_signal(sig)
    _out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err, err
    assert "internal error" not in err, err
    assert err.strip().splitlines()[-1].startswith(f"postproc: stopped by {signal.Signals(sig).name}"), err
    time.sleep(0.3)
    alive = [k for k in kids if Path(f"/proc/{k}").exists() and "Z" not in Path(f"/proc/{k}/stat").read_text()
             .rsplit(")", 1)[1].split()[0]]
    assert not alive, f"children left running: {alive}"
    assert not any(tmp.iterdir()), list(tmp.rglob("*"))
    return err


@pytest.mark.skipif(sys.platform != "linux", reason="the split forks children (Linux)")
@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_a_signal_stops_a_split_correct_and_leaves_no_temporary_file(tmp_path, big, sig):
    out_dir, tmp = tmp_path / "out", tmp_path / "tmp"
    out_dir.mkdir()
    tmp.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "postproc", "correct", str(big), "-c", STATIC, *_setup(tmp_path),
                             "-j", "2", "-o", str(out_dir / "big_corrected.nc")],
                            env=_env(tmp), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for(lambda: any(out_dir.iterdir()) and len(_children(proc.pid)) >= 1)
    time.sleep(0.5)
    _stop(proc, sig, tmp)
    assert not any(out_dir.iterdir()), list(out_dir.iterdir())


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_a_signal_while_a_piped_program_is_read_removes_its_copy(tmp_path, big, sig):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "postproc", "correct", "-", "-c", STATIC, *_setup(tmp_path),
                             "-o", "-"], env=_env(tmp), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    proc.stdin.write(big.read_text()[:200_000])  # the pipe stays open: the copy is half made
    proc.stdin.flush()
    _wait_for(lambda: list(tmp.glob("postproc-*/stdin.nc")))
    time.sleep(0.3)
    _stop(proc, sig, tmp)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=lambda s: signal.Signals(s).name)
def test_a_signal_while_a_piped_program_is_corrected_to_stdout(tmp_path, big, sig):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    with open(big, "rb") as stdin:
        proc = subprocess.Popen([sys.executable, "-m", "postproc", "correct", "-", "-c", STATIC,
                                 *_setup(tmp_path), "-o", "-"], env=_env(tmp), stdin=stdin,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _wait_for(lambda: list(tmp.glob("postproc-*/.out.nc.*")))
        time.sleep(0.3)
        _stop(proc, sig, tmp)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=lambda s: signal.Signals(s).name)
def test_a_signal_stops_a_batch_of_files_with_no_temporary_file_left(tmp_path, big, sig):
    src, out_dir, tmp = tmp_path / "src", tmp_path / "out", tmp_path / "tmp"
    for d in (src, out_dir, tmp):
        d.mkdir()
    text = big.read_text()
    for k in range(3):
        (src / f"p{k}.nc").write_text(text)
    proc = subprocess.Popen([sys.executable, "-m", "postproc", "correct", str(src), "-c", STATIC, *_setup(tmp_path),
                             "-j", "2", "--output-dir", str(out_dir)],
                            env=_env(tmp), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for(lambda: len(list(out_dir.glob(".*.tmp"))) >= 2)
    time.sleep(0.3)
    _stop(proc, sig, tmp)
    assert not list(out_dir.glob(".*")), list(out_dir.iterdir())
