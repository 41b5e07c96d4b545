"""postproc diff: blocks moved, per-axis corrections, inserted and unchanged lines."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calibration.calfile import load_calibration
from postproc.cli import main
from postproc.engine.identity import IdentityEngine
from postproc.errors import PostprocError
from postproc.gcode import emit
from postproc.gcode.compare import compare_programs
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
CASES = ROOT / "tests" / "cases"


def test_diff_counts_match_what_correct_reported():
    cal = load_calibration(CASES / "strong_static.json")
    text = (CASES / "arcs_linearised.nc").read_text()
    out, rep = correct_text(text, cal.engine, Setup(), CorrectOptions())
    d = compare_programs(text, out)
    assert d.lines_inserted == rep.lines_inserted
    assert d.moves == rep.moves
    assert len(d.moved) == rep.moves
    assert d.lines_unchanged == len(text.splitlines()) - rep.moves
    # end points moved by at most the largest correction the pipeline applied anywhere
    biggest = max(m.size_mm for m in d.moved)
    assert 0.9 * rep.max_correction_mm < biggest <= rep.max_correction_mm + 1e-4


def test_diff_of_identity_correction_moves_nothing():
    text = (ROOT / "samples" / "pocket.nc").read_text()
    out, _ = correct_text(text, IdentityEngine([[-1e4] * 3, [1e4] * 3]), Setup())
    d = compare_programs(text, out)
    assert d.moved == []
    assert d.lines_inserted == 0
    assert d.lines_unchanged == len(text.splitlines())
    assert all(v["max_mm"] == 0.0 for v in d.axis_stats().values())


def test_diff_per_axis_statistics():
    cal = load_calibration(CASES / "demo_static.json")
    text = (ROOT / "samples" / "pocket.nc").read_text()
    out, _ = correct_text(text, cal.engine, Setup())
    d = compare_programs(text, out)
    deltas = np.array([m.delta_mm for m in d.moved])
    stats = d.axis_stats()
    for k, a in enumerate("XYZ"):
        assert stats[a]["max_mm"] == pytest.approx(np.abs(deltas[:, k]).max())
        assert stats[a]["mean_mm"] == pytest.approx(np.abs(deltas[:, k]).mean())
    assert stats["X"]["max_mm"] > 0.03  # r_O1 x = 35 um dominates


def test_cli_diff_text_and_json(tmp_path):
    out = tmp_path / "o.nc"
    r = CliRunner().invoke(main, ["correct", str(CASES / "arcs_linearised.nc"), "-c",
                                  str(CASES / "strong_static.json"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["diff", str(CASES / "arcs_linearised.nc"), str(out)])
    assert r.exit_code == 0, r.output
    assert "inserted by segmentation" in r.output
    assert "correction per axis" in r.output
    r = CliRunner().invoke(main, ["diff", str(CASES / "arcs_linearised.nc"), str(out), "--json"])
    data = json.loads(r.output)
    assert data["lines_inserted"] == 3  # one inserted exact arc per ellipse-like corrected arc (was > 100 chords)
    assert data["moves_moved"] == 7
    assert set(data["per_axis"]) == {"X", "Y", "Z"}


def test_diff_of_unrelated_programs_is_an_error():
    a = (ROOT / "samples" / "pocket.nc").read_text()
    b = (ROOT / "samples" / "holes_g91.nc").read_text()
    with pytest.raises(PostprocError):
        compare_programs(a, b)


def test_diff_pairs_steps_shorter_than_the_correction():
    from postproc.engine.static import StaticEngine

    # 0.01 mm steps, 0.2 mm correction: the nearest corrected end point of a step is
    # usually another step's; pairing must still find each step's own line
    eng = StaticEngine(np.eye(3), [0.2, -0.1, 0.05], [[0, 0, 0], [315, 315, 315]])
    text = "G21 G90 G0 X10 Y10 Z10\n" + "".join(f"G1 X{10 + 0.01 * i:.2f}\n" for i in range(1, 400)) + "M2\n"
    out, rep = correct_text(text, eng, Setup())
    d = compare_programs(text, out)
    assert d.moves == rep.moves
    np.testing.assert_allclose(np.array([m.delta_mm for m in d.moved]), [[-0.2, 0.1, -0.05]] * d.n_moved,
                               atol=1e-9)
    n_header = len(emit.split_header(out)[0])
    assert [m.lineno for m in d.moved] == [m.lineno_corrected - n_header for m in d.moved]


def test_diff_of_a_twice_corrected_program_skips_both_headers():
    cal = load_calibration(CASES / "demo_static.json")
    text = (ROOT / "samples" / "pocket.nc").read_text()
    once, _ = correct_text(text, cal.engine, Setup())
    twice, _ = correct_text(once, cal.engine, Setup(), CorrectOptions(force=True))
    d = compare_programs(text, twice)
    assert d.moves == 26
