"""Expansion of Fanuc/Haas subprograms (M98/M99) and custom macro B.

LinuxCNC cannot run macro B, so these are checked against flat text derived by hand
from the Fanuc custom macro B rules (Fanuc Series 0i/16i/30i operator's manuals,
"Custom macro": argument specification I, vacant variables, GOTO/IF/WHILE, the
arithmetic functions); M98/M99, which LinuxCNC 2.9 also runs, is in addition checked
against rs274.
"""

from __future__ import annotations

import pytest
from oracle import requires_rs274, run_rs274, same_motions

from postproc.errors import GcodeSyntaxError, PostprocError
from postproc.gcode.expand import ExpansionError, expand
from postproc.gcode.lexer import split_lines


def flat(text: str, dialect: str = "fanuc", **kw) -> str:
    return "".join(sl.text for sl in expand(split_lines(text), dialect=dialect, **kw))


SUBPROGRAMS = """%
O0100 (MAIN)
G90 G54 G00 X0. Y0.
M98 P1000 L2
M98 P21000
G00 X5.
M30
O1000 (STEP)
G91 G01 X1. F100.
G90
M99
%
"""


def test_m98_repeat_forms_hand_checked():
    step = "G91 G01 X1. F100.\nG90\n"
    assert flat(SUBPROGRAMS) == ("%\nO0100 (MAIN)\nG90 G54 G00 X0. Y0.\n" + step * 4
                                 + "G00 X5.\nM30\n%\n")


def test_m98_lines_carry_their_source_place():
    got = [(sl.lineno, sl.original) for sl in expand(split_lines(SUBPROGRAMS), dialect="haas")]
    assert got == [(1, True), (2, True), (3, True)] + [(9, True), (10, True)] * 4 + [
        (6, True), (7, True), (12, True)]


@requires_rs274
def test_m98_matches_linuxcnc():
    # LinuxCNC 2.9 runs M98 P.. L.. / O.... / M99 the Fanuc way (P21000 as a number, so L here)
    text = "G21 G90 G17 F100\nM98 P1000 L3\nG0 X0 Y#1\nM2\nO1000\n#1 = [#1 + 2]\nG91 G1 X1 Y#1\nG90\nM99\n"
    ref = run_rs274(text)
    assert ref.ok, ref.error
    out = flat(text, dialect="linuxcnc")
    got = run_rs274(out)
    assert got.ok, got.error
    assert same_motions(ref.motions, got.motions) == ""
    assert "G91 G1 X1 Y6.0\n" in out  # M98 shares #1 with its caller: 2, 4, 6


def test_m99_p_returns_to_a_sequence_number():
    text = "O1\nM98 P2\nN10 G0 X1.\nN20 G0 X2.\nM30\nO2\nG0 Z1.\nM99 P20\n"
    assert flat(text) == "O1\nG0 Z1.\nN20 G0 X2.\nM30\n"


def test_a_vacant_variable_in_a_call_address_is_ignored():
    """The control ignores an address holding a vacant variable: L#0 calls once, M99 P#0
    returns to the caller, and M98 P#0 or G65 P#0 is a call without its program number
    (a clear error naming the line and column, not a crash)."""
    step = "G91 G01 X1. F100.\nG90\n"
    assert flat(SUBPROGRAMS.replace("M98 P1000 L2", "M98 P1000 L#0").replace("M98 P21000\n", "")) == (
        "%\nO0100 (MAIN)\nG90 G54 G00 X0. Y0.\n" + step + "G00 X5.\nM30\n%\n")
    assert flat("O1\nM98 P2\nN10 G0 X1.\nN20 G0 X2.\nM30\nO2\nG0 Z1.\nM99 P#0\n") == (
        "O1\nG0 Z1.\nN10 G0 X1.\nN20 G0 X2.\nM30\n")
    assert flat("O1\nG65 P2 L#0 A1.\nM30\nO2\nG0 X#1\nM99\n") == "O1\nG0 X1.0\nM30\n"
    for text, message in (("O1\nM98 P#0\nM30\n", "M98 needs P"), ("O1\nG65 P#0 A1.\nM30\n", "G65 needs P")):
        with pytest.raises(PostprocError, match=message) as err:
            flat(text)
        assert err.value.lineno == 2
        assert err.value.col == 1


def test_macro_variables_if_goto_and_while_hand_checked():
    text = """O2000
#100 = 3
#1 = 0
N10 #1 = #1 + 1
G01 X#1 Y#100 F100.
IF [#1 LT 3] GOTO 10
WHILE [#1 GT 0] DO 1
#2 = 0
WHILE [#2 LT 2] DO 2
#2 = #2 + 1
G01 Z-#2
END 2
#1 = #1 - 1
END 1
IF [#1 EQ 0] THEN #3 = 7.5
G00 Z#3
GOTO 99
G00 Z99.
N99 M30
"""
    inner = "G01 Z-1.0\nG01 Z-2.0\n"
    assert flat(text) == ("O2000\n" + "".join(f"G01 X{k}.0 Y3.0 F100.\n" for k in (1, 2, 3))
                          + inner * 3 + "G00 Z7.5\nN99 M30\n")


def test_goto_searches_forward_then_from_the_program_start():
    text = "O3\n#1 = 0\nN5 #1 = #1 + 1\nIF [#1 GE 3] GOTO 7\nGOTO 5\nN7 G0 X#1\nM30\n"
    assert flat(text) == "O3\nN7 G0 X3.0\nM30\n"


def test_g65_arguments_and_local_levels():
    text = """O4
#1 = 50.
#24 = 60.
G65 P9000 A1. B2. X5. Y-1.5 L2
G00 X#1 Y#24
M30
O9000
#1 = #1 + 1
G00 X[#1 + #2] Y#25 Z#3
M99
"""
    # A -> #1, B -> #2, X -> #24, Y -> #25; C (#3) vacant: Z is left out.
    # The two L2 passes share one local level: #1 = 2 then 3. The caller's #1/#24 are untouched.
    assert flat(text) == "O4\nG00 X4.0 Y-1.5\nG00 X5.0 Y-1.5\nG00 X50.0 Y60.0\nM30\n"


def test_g65_argument_without_decimal_point_is_refused():
    with pytest.raises(ExpansionError) as err:
        flat("O5\nG65 P9000 A1\nM30\nO9000\nM99\n")
    assert (err.value.lineno, err.value.col) == (2, 11)
    assert "decimal point" in str(err.value)


def test_vacant_variables():
    text = """O6
#101 = #0
IF [#101 EQ #0] THEN #102 = 1.
IF [#101 EQ 0] THEN #102 = 2.
#103 = #101
#104 = #101 * 5.
G00 X#102 Y#104
G00 X#103 Y[#0 + 1.]
#105 = #1
IF [#105 NE #0] GOTO 9
G00 Z1.
N9 M30
"""
    # vacant EQ vacant is true, vacant EQ 0 false; #103 = #101 stays vacant (X left out);
    # arithmetic takes vacant as 0; main-level locals start vacant
    assert flat(text) == "O6\nG00 X1.0 Y0.0\nG00 Y1.0\nG00 Z1.\nN9 M30\n"


def test_fanuc_functions_differ_from_linuxcnc():
    text = "O7\nG0 X[FIX[-1.5]] Y[FUP[-1.2]] Z[ROUND[2.5]]\nG0 X[ATAN[-1.]/[-1.]] Y[ATAN[1.,1.]] Z[POW[2.,10.]]\n"\
           "G0 X[7. AND 3.] Y[4. OR 1.] Z[5. XOR 1.]\nG0 X[SQRT[2.]*SQRT[2.]] Y[ABS[-3.]] Z[-7. MOD 3.]\nM30\n"
    assert flat(text) == ("O7\nG0 X-1.0 Y-2.0 Z3.0\nG0 X225.0 Y45.0 Z1024.0\nG0 X3.0 Y5.0 Z4.0\n"
                          "G0 X2.0 Y3.0 Z-1.0\nM30\n")
    # the same expressions read the LinuxCNC way: FIX/FUP are floor/ceiling, MOD is non-negative
    assert flat("G0 X[FIX[-1.5]] Y[FUP[-1.2]] Z[-7 MOD 3]\nM2\n", dialect="linuxcnc") == \
        "G0 X-2.0 Y-1.0 Z2.0\nM2\n"


def test_generic_dialect_recognises_macro_b():
    text = "O8\n#1 = 2\nN3IF[#1GT1]GOTO5\nG0 X9.\nN5 G0 X#1\nM30\n"
    assert flat(text, dialect="generic") == "O8\nN5 G0 X2.0\nM30\n"
    # arithmetic outside brackets is macro B (LinuxCNC wants #1 = [#2 + 3])
    assert flat("#2 = 1.5\n#1 = #2 + 3 * 2\nG0 X#1 Y#7\nM30\n", dialect="generic") == "G0 X7.5\nM30\n"


@pytest.mark.parametrize(
    ("text", "lineno", "col", "words"),
    [
        ("O1\nG0 X#5021\n", 2, 5, ["#5021", "system variable"]),
        ("O1\n#1 = #4001\n", 2, 6, ["#4001", "system variable"]),
        ("O1\n#3000 = 1 (ALARM)\n", 2, 1, ["#3000", "controller state"]),
        ("O1\nG0 X#500\n", 2, 5, ["#500", "retained"]),
        ("O1\nG0 X1.\nM99 P1\n", 3, 1, ["M99", "main program"]),
        ("O1\nWHILE [1 EQ 1] DO 1\nEND 1\n", 3, 1, ["endless loop", "changes nothing"]),
        ("O1\nGOTO 50\nM30\n", 2, 1, ["N50", "not found"]),
        ("O1\nM98 P1234\nM30\n", 2, 5, ["O1234", "not found"]),
        ("O1\nWHILE [1 EQ 1] DO 4\n", 2, 19, ["1, 2 or 3"]),
        ("O1\nG66 P9000 A1.\n", 2, 1, ["G66"]),
        ("O1\nG0 X#<a>\n", 2, 6, ["named parameters", "LinuxCNC"]),
    ],
)
def test_fanuc_errors_name_their_place(text, lineno, col, words):
    with pytest.raises(PostprocError) as err:
        flat(text, path="f.nc", max_lines=100)
    e = err.value
    assert (e.path, e.lineno, e.col) == ("f.nc", lineno, col), str(e)
    for w in words:
        assert w in str(e), str(e)


def test_retained_variable_set_first_may_be_read():
    assert flat("O1\n#500 = 2.5\nG0 X#500\nM30\n") == "O1\nG0 X2.5\nM30\n"


def test_o_word_control_in_fanuc_dialect_is_named():
    with pytest.raises(GcodeSyntaxError) as err:
        flat("o100 sub\n")
    assert "LinuxCNC syntax" in str(err.value)
    assert (err.value.lineno, err.value.col) == (1, 1)


def test_m98_program_file_on_subroutine_path(tmp_path):
    (tmp_path / "5001.NC").write_text("%\nO5001 (W)\nG91 G01 X1. F100.\nG90\nM99\n%\n")
    text = "O1\nM98 P5001 L2 (TWICE)\nM30\n%\n"
    body = "G91 G01 X1. F100.\nG90\n"
    assert flat(text, subroutine_path=[tmp_path]) == "O1\n" + body * 2 + "M30\n%\n"


def test_haas_m97_local_subprogram():
    text = "O9\nM97 P100 L2\nG0 X9.\nM30\nN100 G91 G0 X1.\nG90\nM99\n"
    assert flat(text, dialect="haas") == "O9\n" + "N100 G91 G0 X1.\nG90\n" * 2 + "G0 X9.\nM30\n"


def test_m99_ending_the_main_program_ends_the_pass():
    from postproc.gcode.expand import expand

    text = "O1\nG0 X1.\nM99\nG0 X2.\n"
    out = [sl.text for sl in expand(text.splitlines(keepends=True), dialect="fanuc")]
    assert out == ["O1\n", "G0 X1.\n", "M99\n"]
