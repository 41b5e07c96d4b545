"""The rs274 oracle helper: parsing of canonical output and detection of refusals."""

from __future__ import annotations

import math

import pytest
from oracle import parse_canon, requires_rs274, run_rs274, same_motions

CANON = """\
    1 N..... USE_LENGTH_UNITS(CANON_UNITS_MM)
    7 N..... SELECT_PLANE(CANON_PLANE_XY)
    9 N..... SET_FEED_RATE(100.0000)
   10 N..... STRAIGHT_TRAVERSE(1.0000, 2.0000, 3.0000, 0.0000, 0.0000, 0.0000)
   11 N..... ARC_FEED(10.0000, 0.0000, 5.0000, 0.0000, -1, 0.0000, 0.0000, 0.0000, 0.0000)
   12 N..... SELECT_PLANE(CANON_PLANE_XZ)
   13 N..... ARC_FEED(0.0000, -10.0000, 0.0000, -5.0000, 1, 4.0000, 0.0000, 0.0000, 0.0000)
   14 N..... SELECT_PLANE(CANON_PLANE_YZ)
   15 N..... ARC_FEED(7.0000, 8.0000, 6.0000, 9.0000, 2, -3.0000, 0.0000, 0.0000, 0.0000)
   16 N..... STRAIGHT_FEED(-2.0000, 64.0000, 2.0000, 0.0000, 0.0000, 0.0000)
"""


def test_parse_canon_maps_plane_order_to_xyz():
    motions, calls = parse_canon(CANON)
    assert [m.kind for m in motions] == ["STRAIGHT_TRAVERSE", "ARC_FEED", "ARC_FEED", "ARC_FEED",
                                         "STRAIGHT_FEED"]
    assert motions[0].end[:3] == (1.0, 2.0, 3.0)
    xy = motions[1]
    assert (xy.plane, xy.turn, xy.end[:3], xy.centre) == ("XY", -1, (10.0, 0.0, 0.0), (5.0, 0.0, 0.0))
    # XZ prints (Z, X) then Y
    xz = motions[2]
    assert (xz.plane, xz.turn, xz.end[:3], xz.centre) == ("XZ", 1, (-10.0, 4.0, 0.0), (-5.0, 4.0, 0.0))
    # YZ prints (Y, Z) then X
    yz = motions[3]
    assert (yz.plane, yz.turn, yz.end[:3], yz.centre) == ("YZ", 2, (-3.0, 7.0, 8.0), (-3.0, 6.0, 9.0))
    assert motions[4].end[:3] == (-2.0, 64.0, 2.0)
    assert calls[0] == "USE_LENGTH_UNITS(CANON_UNITS_MM)"
    assert len(calls) == 10


def test_same_motions_reports_first_difference():
    a, _ = parse_canon(CANON)
    b = list(a)
    assert same_motions(a, b) == ""
    b[2] = type(b[2])(b[2].kind, b[2].end, b[2].centre, -b[2].turn, b[2].plane)
    assert same_motions(a, b).startswith("motion 2:")
    assert "motions" in same_motions(a, a[:-1])


@requires_rs274
def test_rs274_runs_a_program_hand_checked():
    # quarter circle of radius 5 about (5, 0), from the origin, CW to (5, 5)
    res = run_rs274("G21 G17 G90\nG0 X0 Y0 Z1\nG1 Z0 F100\nG2 X5 Y5 I5 J0\nM2\n")
    assert res.ok, res.error
    kinds = [m.kind for m in res.motions]
    assert kinds == ["STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "ARC_FEED"]
    arc = res.motions[2]
    assert arc.end[:3] == (5.0, 5.0, 0.0)
    assert arc.centre == (5.0, 0.0, 0.0)
    assert arc.turn == -1
    assert math.isclose(math.dist(arc.end[:2], arc.centre[:2]), 5.0)


@requires_rs274
@pytest.mark.parametrize(
    ("program", "message"),
    [
        ("G21\nG1 F100 X[1/0]\nM2\n", "divide by zero"),
        ("G21\nG1 F100 X#<nope>\nM2\n", "#<nope> not defined"),
        ("G21\nG1 F100 X1\n", "no percent sign or program end"),
    ],
)
def test_rs274_refusal_is_detected(program, message):
    res = run_rs274(program)
    assert not res.ok
    assert message in res.error


@requires_rs274
def test_rs274_tools_params_and_subroutine_files():
    res = run_rs274("G21\nT2 M6\nG43\nG0 X#5221\no<sq> call [3]\nM98 P5001\nM2\n",
                    tools="T2 P2 Z7 D4\n", params={5221: 12.5},
                    files={"sq.ngc": "o<sq> sub\nG1 F100 Y#1\no<sq> endsub\nM2\n",
                           "5001.ngc": "O5001\nG1 F100 Z-1\nM99\n"})
    assert res.ok, res.error
    assert [m.end[:2] for m in res.motions] == [(12.5, 0.0), (12.5, 3.0), (12.5, 3.0)]
    # canonical positions stay in program coordinates; the tool length comes as its own call,
    # in mm here because standalone rs274 reads the tool table in inches (7 in = 177.8 mm)
    assert res.motions[-1].end[2] == pytest.approx(-1.0)
    assert any(c.startswith("USE_TOOL_LENGTH_OFFSET(0.0000 0.0000 177.8000") for c in res.calls)
