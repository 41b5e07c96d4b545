"""Sinumerik CASE branches (Job planning, "Program branch (CASE ... OF ... DEFAULT ...)"):
the jump of the constant equal to the expression's value, else DEFAULT's, else the next
block; expanded into a flat program like the other control structures."""

import pytest

from postproc.errors import PostprocError, UnsupportedGcodeError
from postproc.gcode.expand import expand

BODY = ("N10 CASE (SEL+1) OF 1 GOTOF ONE 3 GOTOF THREE{default}\n"
        "G1 X7\n"
        "ONE: G1 X1\nGOTOF DONE\nTHREE: G1 X3\nGOTOF DONE\nOTHER: G1 X9\nDONE:\nM30\n")


def flat(sel, default=" DEFAULT GOTOF OTHER"):
    text = f"%_N_C_MPF\nDEF INT SEL={sel}\nG0 X0 Y0 Z10\n" + BODY.format(default=default)
    return [ln for ln in (sl.text for sl in expand(text.splitlines(keepends=True), path="c.mpf",
                                                   dialect="sinumerik")) if ln.startswith("G1")]


@pytest.mark.parametrize(("sel", "moves"), [
    (0, ["G1 X1\n"]),  # 0 + 1 == 1: ONE
    (2, ["G1 X3\n"]),  # 2 + 1 == 3: THREE
    (5, ["G1 X9\n"]),  # no constant: DEFAULT
])
def test_case_jumps_by_hand(sel, moves):
    assert flat(sel) == moves


def test_case_without_default_runs_the_next_block():
    # 6 matches nothing and there is no DEFAULT: the block after CASE (G1 X7), then ONE's
    assert flat(5, default="") == ["G1 X7\n", "G1 X1\n"]


def test_case_branch_with_a_string_constant_refused_by_name():
    text = "%_N_C_MPF\nDEF INT SEL=1\nN10 CASE SEL OF 'HC' GOTOF A DEFAULT GOTOF A\nA: G1 X1\nM30\n"
    with pytest.raises(UnsupportedGcodeError, match=r"Sinumerik CASE branch \"'HC' GOTOF A") as err:
        list(expand(text.splitlines(keepends=True), path="c.mpf", dialect="sinumerik"))
    assert (err.value.lineno, err.value.col) == (3, 5)


def test_case_to_a_missing_label_refused():
    text = "%_N_C_MPF\nDEF INT SEL=1\nCASE (SEL) OF 1 GOTOF NOWHERE\nM30\n"
    with pytest.raises(PostprocError, match="GOTOF NOWHERE: jump label not found"):
        list(expand(text.splitlines(keepends=True), path="c.mpf", dialect="sinumerik"))


def test_case_program_corrected():
    """The interpreter sends a CASE program to the expansion (the dialect's control
    constructs), and the branch taken is corrected."""
    from postproc.engine.identity import IdentityEngine
    from postproc.gcode.path import Setup
    from postproc.gcode.pipeline import CorrectOptions, correct_text

    text = "%_N_C_MPF\nG54 D1\nDEF INT SEL=2\nG0 X0 Y0 Z10\n" + BODY.format(default=" DEFAULT GOTOF OTHER")
    out, rep = correct_text(text, IdentityEngine([[-1e5] * 3, [1e5] * 3]),
                            Setup(offsets={"G54": (0.0, 0.0, 0.0)}, tool_lengths={1: 0.0}),
                            CorrectOptions(dialect="sinumerik"), path="c.mpf")
    assert rep.expanded
    assert "G1 X3\n" in out
    assert "X9" not in out
    assert "CASE" not in out
