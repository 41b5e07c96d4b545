"""What each controller accepts: line length, comments, case, decimals, and its arc rule.

A corrected program must load on the controller it is for. ``DIALECTS`` holds one
``Dialect`` per controller that ``--dialect`` names; ``generic`` is the subset every
one of them accepts (the shortest line, upper case, parenthesis comments holding no
``;``, ``,`` or ``(``, ASCII only).

Where a value comes from the controller's source, the file and the constant are named
beside it. LinuxCNC's values were also checked against its own interpreter (``rs274``
of Debian's linuxcnc-uspace 2.9.0~pre1): a 252-character line loads, a 253-character
line is "Command too long"; the arc rule below accepts and refuses the same arcs.
Values from the Fanuc and Haas manuals are machine parameters: the defaults here are
the usual settings, and are said to be so.

The input-arc rule: a centre-format arc (I/J/K) whose end point is not at the start
radius from the centre. ``Dialect.arc_end_radius_tolerance(r_start_mm, units)`` is how
far the end radius may differ from the start radius before that controller refuses the
block; ``arc_mismatch`` says what it does with a difference inside that tolerance.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import TypedDict

from postproc.constants import MM_PER_INCH
from postproc.errors import PostprocError

# --- LinuxCNC ------------------------------------------------------------------------
# src/emc/linuxcnc.h: LINELEN 255. src/emc/rs274ngc/interp_read.cc (read_text) reads with
# fgets(line, LINELEN, fp) and fails with NCE_COMMAND_TOO_LONG when strlen(line) ==
# LINELEN - 1: the stored text includes the line feed, so 253 characters (254 with "\n")
# is refused and 252 is the longest line that loads (251 with "\r\n").
LINUXCNC_LINELEN = 255
# src/emc/rs274ngc/interp_internal.hh:
#   CENTER_ARC_RADIUS_TOLERANCE_INCH (2 * 0.001 * M_SQRT2)   absolute, program units (inch)
#   CENTER_ARC_RADIUS_TOLERANCE_MM   (2 * 0.01 * M_SQRT2)    absolute, program units (mm)
#   SPIRAL_RELATIVE_TOLERANCE 0.001                          relative to max(r_start, r_end)
# src/emc/rs274ngc/interp_arc.cc (arc_data_ijk): error when
#   abs_err > spiral_abs_tolerance * 100.0  ||  (rel_err > spiral_rel_tolerance && abs_err > spiral_abs_tolerance)
# so the absolute tolerance alone passes small arcs, the relative one large arcs, and
# 100 times the absolute tolerance is the cap. (rs274 2.9.0: 0.05 mm on r = 100 loads,
# 0.05 mm on r = 10 is refused, 2.85 mm on r = 10000 is refused.)
LINUXCNC_ARC_ABS_MM = 2 * 0.01 * math.sqrt(2.0)
LINUXCNC_ARC_ABS_INCH = 2 * 0.001 * math.sqrt(2.0)
LINUXCNC_ARC_REL = 0.001
LINUXCNC_ARC_CAP_FACTOR = 100.0

# --- Grbl (1.1) --------------------------------------------------------------------
# grbl/gcode.c, centre-format arcs (IJK already converted to mm):
#   if (delta_r > 0.005) { if (delta_r > 0.5) FAIL(STATUS_GCODE_INVALID_TARGET);
#                          if (delta_r > (0.001*gc_block.values.r)) FAIL(STATUS_GCODE_INVALID_TARGET); }
# with gc_block.values.r the start radius. Always millimetres, whatever G20/G21.
GRBL_ARC_ABS_MM = 0.005
GRBL_ARC_CAP_MM = 0.5
GRBL_ARC_REL = 0.001
# grbl/protocol.c keeps a line's words, without blanks and comments, in
# line[LINE_BUFFER_SIZE] (LINE_BUFFER_SIZE 80, protocol.h) and reports an overflow
# once char_counter >= LINE_BUFFER_SIZE-1: at most 79 characters of words.
GRBL_LINE_BUFFER_SIZE = 80
# grbl/serial.h RX_BUFFER_SIZE 128: senders that stream by character counting send
# the whole line, comments included, and it must fit the receive buffer with its "\n".
GRBL_RX_BUFFER_SIZE = 128

# --- NIST RS274NGC 3 (the interpreter Mach3 is built on) ------------------------------
# rs274ngc.hh: RS274NGC_TEXT_SIZE 256, TOLERANCE_INCH 0.0002, TOLERANCE_MM 0.002; arc_data_ijk
# refuses fabs(radius - radius2) > tolerance. The line is read like LinuxCNC's (fgets into
# RS274NGC_TEXT_SIZE, too long at TEXT_SIZE - 1): 253 characters load; 252 is kept here
# as LinuxCNC's, one below, because Mach3's own reader is not published.
NIST_ARC_ABS_MM = 0.002
NIST_ARC_ABS_INCH = 0.0002

# --- Fanuc / Haas (manuals) ----------------------------------------------------------
# Fanuc parameter 3410 "tolerance of arc radius" (input unit): a centre-format arc whose
# end radius differs from its start radius by more than it raises alarm PS0020 (OVER
# TOLERANCE OF RADIUS); inside it the arc is cut as a spiral. The value is the machine
# builder's: 0.020 mm (0.0008 in) is assumed here, a common setting; give programs for a
# machine set tighter arcs that agree within its value.
FANUC_ARC_ABS_MM = 0.020
FANUC_ARC_ABS_INCH = 0.0008
# Haas mills alarm "Invalid I, J, K, or R in G02 or G03" for an end point off the start
# radius; the same tolerance is assumed (not documented as a number in the operator's manual).
HAAS_ARC_ABS_MM = 0.020
HAAS_ARC_ABS_INCH = 0.0008
# Fanuc and Haas program memory: no block limit is given in the operator's manuals for
# milling programs; DNC links and older memory formats break long blocks. 128 characters
# is kept as the limit here (the header and every edited line stay far below it).
FANUC_MAX_LINE = 128
# Fanuc lathe (G code system A): G70 finishing, G71 stock removal in turning, G72 in facing,
# G73 pattern repeating, G74 end face peck drilling, G75 outer/inner diameter grooving, G76
# multiple threading. G73 and G76 are milling cycles on a mill (peck drilling, fine boring),
# and G74 is left-hand tapping: only the others are read as a lathe's, and only after G96.
FANUC_TURNING_CYCLES = frozenset({700, 710, 720, 750})


@dataclass(frozen=True)
class Dialect:
    name: str
    title: str
    max_line_chars: int  # characters of a line, line feed not counted (a carriage return is)
    max_word_chars: int | None  # characters of words left after blanks and comments go (Grbl)
    uppercase_only: bool  # letters must be upper case, comments included (Fanuc/Haas)
    paren_comments: bool  # "( ... )"
    semicolon_comments: bool  # "; ..." to the end of the line
    comment_forbidden: str  # characters that must not appear inside a comment
    nested_comments: str  # what the controller does with "(" inside a comment
    ascii_only: bool  # only printable ASCII (ISO code) in the program
    decimals_mm: int  # default decimals of written coordinates
    decimals_inch: int
    arc_rule: str  # linuxcnc | grbl | absolute | strictest
    arc_abs_mm: float  # absolute tolerance in a G21 program (mm)
    arc_abs_inch: float  # absolute tolerance in a G20 program (inch)
    arc_rel: float  # relative tolerance (0: none)
    arc_cap_mm: float  # largest tolerance whatever the radius, mm (G21); inf: none
    arc_mismatch: str  # what the controller does with an arc inside the tolerance, and beyond it
    source: str  # where the values come from
    # -- how programs are read (the interpreter and the expansion ask for these) --------
    machine: str = "mill"  # mill | lathe: postproc corrects milling machines only
    reads_arcs_as: str | None = None  # the dialect whose input-arc rule applies (None: its own)
    comments_nest: bool = False  # "(a (b) c)" is one comment (else LinuxCNC/Grbl: an error or ')' closes)
    nested_comment_error: bool = False  # a "(" inside a comment is an error (NCE_NESTED_COMMENT_FOUND)
    text_after_percent: str = "ignored"  # "%" followed by text: ignored | error
    g80_clears_motion: bool = False  # G80 leaves no motion mode (else the one before the cycle comes back)
    cycle_keeps_rz: bool = False  # a new canned cycle keeps the last R and Z (else they must be given again)
    cycle_r_default_initial: bool = False  # a cycle without R retracts to the initial level
    cycle_repeat_words: str = "L"  # the words counting a cycle's repeats, first given wins ("KL": K, else L)
    full_circle_without_end: bool = True  # G2/G3 with centre words and no end point is a full circle
    g53_absolute_in_g91: bool = False  # G53 words are machine positions in G91 too (else an error)
    # an I/J/K word off the arc's plane: error | ignored | ignored-beside-centre (ignored where
    # the arc has centre words, an error beside R) | zero-ignored (a zero one beside centre words)
    off_plane_arc_offset: str = "error"
    # parameters and control: o-word (LinuxCNC) | macro-b (Fanuc custom macro B, M98/M99) | detect
    macro_syntax: str = "o-word"
    m98_count_in_p: bool = False  # M98 P(count)(4-digit number) when no program has the whole number
    numbered_program_line: bool = False  # "N1 O2 (NAME)": a program number after a sequence number (Fadal)
    header_forms: tuple[str, ...] = ()  # regexes of header lines read as no geometry ("$NAME.MIN%", Okuma)
    call_o_statement: bool = False  # "CALL O<name> [Q<n>]" runs subprogram O<name> to its RTS (Okuma)
    uvw_axes: bool = False  # U, V, W are axes (LinuxCNC); else U/W mark a lathe program (incremental X/Z)
    turning_cycles: frozenset[int] = frozenset()  # G keys (10 x number) that are lathe turning cycles here
    call_words: str = ""  # letters that call a subroutine in a block without G codes ("L": Fadal format 1)
    fixture_offset_word: str = ""  # a letter selecting a fixture offset by number ("E": Fadal E1..E48)
    g15_work_select: bool = False  # "G15 H<n>" selects work coordinate system n (Okuma)
    g_aliases: tuple[tuple[int, int], ...] = ()  # (this dialect's G key, the ISO G key it means)
    radius_word: str = "R"  # how an arc's radius is written ("CR=" on Sinumerik)
    block_syntax: str = "iso"  # iso: letter-number words | sinumerik: also NAME=value, keywords, calls
    program_end_m: tuple[int, ...] = (2, 30)  # M codes that end the program
    work_codes: tuple[tuple[int, str], ...] = ()  # further work-offset G codes (G key, the offset's name)
    refused_g: tuple[tuple[int, str, str], ...] = ()  # (G key, construct in the dialect's words, what instead)
    dwell_f_is_time: bool = False  # "G4 F2": F is the dwell time, the feed stays (Sinumerik)
    tool_length_word: str = ""  # a word applying a tool length register by number ("D": Sinumerik flat D)
    chosen_by: tuple[str, ...] = ()  # regexes of opening lines that choose this dialect over generic
    yields_to_headers: bool = False  # a program opening with another dialect's chosen_by lines is read in it
    marks: tuple[tuple[str, str], ...] = ()  # (regex, construct) that only this dialect's programs hold
    refused: tuple[tuple[str, str, str], ...] = ()  # (regex, construct in its words, what to post instead)
    # the refused constructs (their names above) the expansion flattens (NeedsExpansion, then
    # the program is corrected flat): Sinumerik's labels, jumps and control structures
    expanded_constructs: frozenset[str] = frozenset()
    # cutter radius compensation (G41/G42): "d-tool" (D names a tool; LinuxCNC's entry, exit and
    # plane rules), "d-register" (D names an offset register; no arc as the start-up or exit move,
    # alarm PS0034) or "none" (the controller has none, or postproc does not model its rules)
    cutter_comp: str = "d-tool"
    comp_controller: str = ""  # the controller named in compensation messages ("": the title)

    def arc_end_radius_tolerance(self, r_start_mm: float, units: str | float = "mm") -> float:
        """Largest |r_end - r_start| (mm) this controller accepts on a centre-format arc.

        ``units``: the program's units, ``"mm"`` or ``"inch"`` (or the factor 1.0 or 25.4),
        because LinuxCNC's and Fanuc's tolerances are set in program units. LinuxCNC's
        relative test divides by the larger radius: taking the start radius gives the
        exact limit when the end radius is the smaller, and one that is smaller by 0.1 %
        of itself otherwise (the safe side); :meth:`arc_end_radius_ok` is exact.
        """
        inch = _is_inch(units)
        r = abs(float(r_start_mm))
        if self.arc_rule == "strictest":
            return min(DIALECTS[n].arc_end_radius_tolerance(r, units) for n in _ALL_BUT_GENERIC)
        if self.arc_rule == "grbl":
            return min(GRBL_ARC_CAP_MM, max(GRBL_ARC_ABS_MM, GRBL_ARC_REL * r))
        a = self.arc_abs_inch * MM_PER_INCH if inch else self.arc_abs_mm
        if self.arc_rule == "linuxcnc":
            return min(LINUXCNC_ARC_CAP_FACTOR * a, max(a, self.arc_rel * r))
        if self.arc_rule == "relative":
            return max(a, self.arc_rel * r)
        return a

    def arc_end_radius_ok(self, r_start_mm: float, r_end_mm: float, units: str | float = "mm") -> bool:
        """Would this controller accept a centre-format arc with these start and end radii?"""
        if self.arc_rule == "strictest":
            return all(DIALECTS[n].arc_end_radius_ok(r_start_mm, r_end_mm, units) for n in _ALL_BUT_GENERIC)
        r0, r1 = abs(float(r_start_mm)), abs(float(r_end_mm))
        err = abs(r1 - r0)
        if self.arc_rule == "linuxcnc":
            a = self.arc_abs_inch * MM_PER_INCH if _is_inch(units) else self.arc_abs_mm
            rel = err / max(r0, r1) if max(r0, r1) > 0 else 0.0
            return not (err > LINUXCNC_ARC_CAP_FACTOR * a or (rel > self.arc_rel and err > a))
        return err <= self.arc_end_radius_tolerance(r0, units)

    def decimals(self, units: str | float = "mm") -> int:
        return self.decimals_inch if _is_inch(units) else self.decimals_mm


def _is_inch(units: str | float) -> bool:
    if isinstance(units, str):
        u = units.strip().lower()
        if u in ("mm", "g21"):
            return False
        if u in ("in", "inch", "g20"):
            return True
        raise ValueError(f"units must be 'mm' or 'inch', got {units!r}")
    return abs(float(units) - MM_PER_INCH) < 1e-9


DIALECTS: dict[str, Dialect] = {
    "linuxcnc": Dialect(
        name="linuxcnc", title="LinuxCNC 2.9",
        max_line_chars=LINUXCNC_LINELEN - 3, max_word_chars=None,
        uppercase_only=False, paren_comments=True, semicolon_comments=True,
        comment_forbidden="(", nested_comments="error (NCE_NESTED_COMMENT_FOUND)", ascii_only=False,
        decimals_mm=4, decimals_inch=5,
        arc_rule="linuxcnc", arc_abs_mm=LINUXCNC_ARC_ABS_MM, arc_abs_inch=LINUXCNC_ARC_ABS_INCH,
        arc_rel=LINUXCNC_ARC_REL, arc_cap_mm=LINUXCNC_ARC_CAP_FACTOR * LINUXCNC_ARC_ABS_MM,
        arc_mismatch="cut as a spiral from the start radius to the end radius; beyond the tolerance the "
                     "block is an error ('Radius to end of arc differs from radius to start')",
        source="linuxcnc.h LINELEN; interp_read.cc read_text; interp_internal.hh CENTER_ARC_RADIUS_TOLERANCE_*, "
               "SPIRAL_RELATIVE_TOLERANCE; interp_arc.cc arc_data_ijk",
        # interp_read.cc read_comment: NCE_NESTED_COMMENT_FOUND; read_text: "Bad character '%' used";
        # interp_convert.cc convert_motion(G_80): motion mode G_80 (none)
        nested_comment_error=True, text_after_percent="error", g80_clears_motion=True,
        # LinuxCNC machines may have U/V/W axes; G70/G71/G72 are its lathe finishing and roughing cycles
        uvw_axes=True, turning_cycles=frozenset({700, 710, 720})),
    "grbl": Dialect(
        name="grbl", title="Grbl 1.1",
        max_line_chars=GRBL_RX_BUFFER_SIZE - 1, max_word_chars=GRBL_LINE_BUFFER_SIZE - 1,
        uppercase_only=False, paren_comments=True, semicolon_comments=True,
        comment_forbidden="(", nested_comments="the first ')' closes the comment; the rest is read as words",
        ascii_only=True, decimals_mm=3, decimals_inch=4,
        arc_rule="grbl", arc_abs_mm=GRBL_ARC_ABS_MM, arc_abs_inch=GRBL_ARC_ABS_MM / MM_PER_INCH,
        arc_rel=GRBL_ARC_REL, arc_cap_mm=GRBL_ARC_CAP_MM,
        arc_mismatch="cut on the start radius (mc_arc), the last segment going straight to the end point; "
                     "beyond the tolerance error 33 (STATUS_GCODE_INVALID_TARGET)",
        source="gcode.c (arc radius check), protocol.c/protocol.h LINE_BUFFER_SIZE, serial.h RX_BUFFER_SIZE; "
               "N_DECIMAL_COORDVALUE_MM/INCH (config.h) for the decimals",
        # gcode.c: an arc with no axis words is STATUS_GCODE_NO_AXIS_WORDS
        full_circle_without_end=False, cutter_comp="none",
        # gcode.c: the centre-offset form clears I, J and K whatever the plane; beside R they
        # are unused words (STATUS_GCODE_UNUSED_WORDS)
        off_plane_arc_offset="ignored-beside-centre"),
    "fanuc": Dialect(
        name="fanuc", title="Fanuc 0i/30i (ISO code)",
        max_line_chars=FANUC_MAX_LINE, max_word_chars=None,
        uppercase_only=True, paren_comments=True, semicolon_comments=False,
        comment_forbidden="(;,", nested_comments="alarm", ascii_only=True,
        decimals_mm=3, decimals_inch=4,
        arc_rule="absolute", arc_abs_mm=FANUC_ARC_ABS_MM, arc_abs_inch=FANUC_ARC_ABS_INCH, arc_rel=0.0,
        arc_cap_mm=FANUC_ARC_ABS_MM,
        arc_mismatch="cut as a spiral (radius changing linearly); beyond parameter 3410 alarm PS0020 "
                     "OVER TOLERANCE OF RADIUS",
        source="Fanuc operator's manual (control-out/control-in comments, ';' is the end of block in ISO "
               "code); parameter manual No. 3410",
        comments_nest=True, cycle_keeps_rz=True, cycle_r_default_initial=True, cycle_repeat_words="KL",
        g53_absolute_in_g91=True, off_plane_arc_offset="ignored", macro_syntax="macro-b", m98_count_in_p=True,
        turning_cycles=FANUC_TURNING_CYCLES, cutter_comp="d-register"),
    "haas": Dialect(
        name="haas", title="Haas NGC",
        max_line_chars=FANUC_MAX_LINE, max_word_chars=None,
        uppercase_only=True, paren_comments=True, semicolon_comments=False,
        comment_forbidden="(;,", nested_comments="alarm", ascii_only=True,
        decimals_mm=3, decimals_inch=4,
        arc_rule="absolute", arc_abs_mm=HAAS_ARC_ABS_MM, arc_abs_inch=HAAS_ARC_ABS_INCH, arc_rel=0.0,
        arc_cap_mm=HAAS_ARC_ABS_MM,
        arc_mismatch="alarm 'Invalid I, J, K, or R in G02 or G03' beyond the tolerance",
        source="Haas mill operator's manual (comments, program format); tolerance assumed as Fanuc's",
        comments_nest=True, cycle_keeps_rz=True, cycle_r_default_initial=True, cycle_repeat_words="KL",
        g53_absolute_in_g91=True, off_plane_arc_offset="ignored", macro_syntax="macro-b", m98_count_in_p=True,
        cutter_comp="d-register"),
    "mach3": Dialect(
        name="mach3", title="Mach3",
        max_line_chars=LINUXCNC_LINELEN - 3, max_word_chars=None,
        uppercase_only=False, paren_comments=True, semicolon_comments=False,
        comment_forbidden="(", nested_comments="error", ascii_only=True,
        decimals_mm=4, decimals_inch=5,
        arc_rule="absolute", arc_abs_mm=NIST_ARC_ABS_MM, arc_abs_inch=NIST_ARC_ABS_INCH, arc_rel=0.0,
        arc_cap_mm=NIST_ARC_ABS_MM,
        arc_mismatch="beyond the tolerance the block is an error (NIST RS274NGC arc_data_ijk)",
        source="NIST RS274NGC 3 rs274ngc.hh TOLERANCE_MM/TOLERANCE_INCH, RS274NGC_TEXT_SIZE",
        comments_nest=True, off_plane_arc_offset="ignored"),
}
# generic is the subset these controllers all accept (later entries are not part of it)
_ALL_BUT_GENERIC = tuple(DIALECTS)
_GENERIC_OF = [DIALECTS[n] for n in _ALL_BUT_GENERIC]

DIALECTS["generic"] = Dialect(
    name="generic", title="every dialect above",
    max_line_chars=min(d.max_line_chars for d in _GENERIC_OF),
    max_word_chars=min(d.max_word_chars for d in _GENERIC_OF if d.max_word_chars),
    uppercase_only=True, paren_comments=True, semicolon_comments=False,
    comment_forbidden="".join(sorted(set("".join(d.comment_forbidden for d in _GENERIC_OF)))),
    nested_comments="refused", ascii_only=True,
    decimals_mm=4, decimals_inch=5,
    arc_rule="strictest", arc_abs_mm=min(d.arc_abs_mm for d in _GENERIC_OF),
    arc_abs_inch=min(d.arc_abs_inch for d in _GENERIC_OF), arc_rel=0.0,
    arc_cap_mm=min(d.arc_cap_mm for d in _GENERIC_OF),
    arc_mismatch="the strictest of the dialects: an arc is accepted only where every controller accepts it",
    source="the intersection of the others",
    # input is read as LinuxCNC (the reference interpreter) reads it, macro programs in the
    # syntax they are written in
    reads_arcs_as="linuxcnc", cutter_comp="d-tool", comp_controller="LinuxCNC", off_plane_arc_offset="zero-ignored",
    macro_syntax="detect", m98_count_in_p=True,
    yields_to_headers=True,
    turning_cycles=FANUC_TURNING_CYCLES)

# --- controllers whose programs generic does not read (each one entry) ---------------------
_FANUC = DIALECTS["fanuc"]
DIALECTS["fanuc-lathe"] = replace(
    _FANUC, name="fanuc-lathe", title="Fanuc 0i-T/30i lathe", machine="lathe",
    source="Fanuc lathe operator's manual (G code system A): postproc corrects milling machines only")

# Fadal (CNC 88HS, "Fadal format 1" native and "format 2" Fanuc-like codes, setting FO): the
# program starts "N1 O2 (NAME)", E1..E48 select fixture offsets (E0 cancels them). Comments,
# line length and arc tolerance as Fanuc's (assumed, the manual gives no figure).
DIALECTS["fadal"] = replace(
    _FANUC, name="fadal", title="Fadal CNC 88HS", numbered_program_line=True, fixture_offset_word="E", call_words="L",
    cycle_repeat_words="L", turning_cycles=frozenset(),
    marks=((r"^\s*N\s*\d+\s*O\s*\d+\b", "N1 O.. program header (Fadal)"),),
    refused=((r"^\s*(?:N\d+\s*)?#", "# macro statement (Fadal macro language)",
              "post the program with numbers in place of the macro"),
             (r"(?i)^\s*(?:N\d+\s*)?L\d{2,4}\b", "L subroutine call (format 1)",
              "write the subroutine's moves in the main program")),
    source="Fadal VMC programming manual: program header N1 O.., fixture offsets E1-E48 (E0 cancel); "
           "format 2 reads Fanuc's G codes")

# Okuma OSP-P (mill, OSP-P200M/P300M): a program file starts "$NAME.MIN%"; G15 H<n> selects
# work coordinate system n, G56 H<n> applies tool length offset n and G53 cancels it, CALL O<n>
# calls a subprogram. Comments in parentheses; the other limits as Fanuc's (assumed).
DIALECTS["okuma"] = replace(
    _FANUC, name="okuma", title="Okuma OSP", header_forms=(r"^\s*\$[^%\r\n]*%\s*$",),
    g15_work_select=True, g_aliases=((560, 430), (530, 490)), cycle_repeat_words="L",
    turning_cycles=frozenset(), macro_syntax="o-word", m98_count_in_p=False,
    marks=((r"^\s*\$[\w.\-]*\.(?:MIN|SDF|SSB|SUB|LIB)%?", "$NAME.MIN% program header (Okuma)"),
           (r"(?i)^\s*(?:N\d+\s*)?CALL\s+O", "CALL O.. subprogram call (Okuma)"),
           (r"^\s*(?:N\d+\s*)?G\s*15\s*H\s*\d", "G15 H.. work coordinate system (Okuma)")),
    call_o_statement=True, expanded_constructs=frozenset({"CALL O.. subprogram call"}),
    refused=((r"(?i)\bCALL\s*O\w*", "CALL O.. subprogram call",
              "give the folder of its .SSB/.SUB/.LIB file with --subroutine-path, or write its moves in the main "
              "program"),
             (r"(?i)^\s*O([A-Z][A-Z0-9]*)\s*(?:\(.*)?$", "O{0} subprogram name line (a subprogram file, not a "
              "main program)", "correct the main program that calls it, with this file's folder on "
              "--subroutine-path"),
             (r"(?i)\bMODIN\b", "MODIN modal subprogram call", "write the subprogram's moves in the main program"),
             (r"(?i)\bV[CS]\d+\s*=", "VC/VS common variable", "post the program with numbers in place of variables"),
             (r"(?i)\b(V[A-Z]{2,}\w*)\s*\[", "{0}[..] system variable", "post the program with numbers in place of "
              "variables"),
             (r"(?i)^\s*(?:N\w+\s+)?([A-Z]{2}[A-Z0-9]{0,2})\s*=(?!=)", "{0}= local variable setting",
              "post the program with numbers in place of variables"),
             (r"(?i)\bIF\s*\[|\bGOTO\b", "IF/GOTO program control", "post the program flat (loops written out)")),
    source="Okuma OSP-P programming manual (Mill): $ file header, G15/G16 work coordinates, "
           "G56/G53 tool length offset, CALL O subprograms")

# Siemens Sinumerik 840D sl (SINUMERIK 840D sl Programming Manual, Fundamentals and Job
# planning): ";" comments; a block of at most 512 characters; circle end point monitoring by
# machine data MD21000 CIRCLE_ERROR_CONST (0.01 mm) and MD21010 CIRCLE_ERROR_FACTOR (0.001):
# the radii may differ by the larger of the two (Fundamentals, "Circular interpolation").
SINUMERIK_MAX_LINE = 511
SINUMERIK_ARC_ABS_MM = 0.01
SINUMERIK_ARC_REL = 0.001
_SINU_SUB = "subprogram call, PROC or EXTERN"
_SINU_CONTROL = "program control (label, IF/WHILE/LOOP/FOR/REPEAT/GOTO)"
_SINU_WHAT_INSTEAD = "post the machining as its moves (G1/G2/G3) instead of the cycle call"
DIALECTS["sinumerik"] = Dialect(
    name="sinumerik", title="Sinumerik 840D (Siemens)", cutter_comp="none",
    max_line_chars=SINUMERIK_MAX_LINE, max_word_chars=None,
    uppercase_only=False, paren_comments=False, semicolon_comments=True,
    comment_forbidden="", nested_comments="not a comment: '(' belongs to expressions", ascii_only=True,
    decimals_mm=3, decimals_inch=4,
    arc_rule="relative", arc_abs_mm=SINUMERIK_ARC_ABS_MM, arc_abs_inch=SINUMERIK_ARC_ABS_MM / MM_PER_INCH,
    arc_rel=SINUMERIK_ARC_REL, arc_cap_mm=math.inf,
    arc_mismatch="alarm 14040 'Error in end point of circle' beyond the tolerance",
    source="SINUMERIK 840D sl Programming Manual Fundamentals (comments, block length, circular "
           "interpolation, CR=, AC/IC, frames) and Job planning (DEF, R parameters, control "
           "structures); Programming Manual Cycles (CYCLE81-89, POCKET1-4, SLOT1-2, CYCLE61-72, CYCLE800); "
           "MD21000/MD21010",
    text_after_percent="ignored", g80_clears_motion=True, macro_syntax="sinumerik", m98_count_in_p=False,
    chosen_by=(r"\s*%_N_\w+_(?:MPF|SPF)\b", r"\s*;\s*\$PATH\s*="),
    expanded_constructs=frozenset({_SINU_CONTROL, _SINU_SUB}),
    block_syntax="sinumerik", radius_word="CR=", program_end_m=(2, 17, 30), dwell_f_is_time=True, tool_length_word="D",
    # G500 (settable frames off) and G505-G599 are work offsets; G64x continuous path, G60/G60x/G9
    # exact stop, G70/G71 and G700/G710 inch/metric (Fundamentals: "Inch/metric dimensions")
    work_codes=((5000, "G500"), *((k * 10, f"G{k}") for k in range(505, 600))),
    g_aliases=((6410, 640), (6420, 640), (6430, 640), (6440, 640), (6450, 640), (600, 610), (6010, 610),
               (6020, 610), (6030, 610), (90, 610), (700, 200), (710, 210), (7000, 200), (7100, 210)),
    refused_g=((530, "G53 (frames suppressed for the block: the tool length stays)",
                "write the move in the work coordinates"),
               (1530, "G153 (frames suppressed for the block)", "write the move in the work coordinates"),
               (330, "G33 thread cutting", "post the thread as its moves"),
               (3310, "G331 rigid tapping", "post the tapping as ISO G84 with --dialect generic, or as moves"),
               (3320, "G332 tapping retraction", "post the tapping as its moves"),
               (1100, "G110 polar pole", "post the program in Cartesian coordinates"),
               (1110, "G111 polar pole", "post the program in Cartesian coordinates"),
               (1120, "G112 polar pole", "post the program in Cartesian coordinates"),
               (580, "G58 axial programmable offset", "post the program without programmable frames"),
               (590, "G59 axial programmable offset", "post the program without programmable frames")),
    marks=((r"^\s*%_N_\w+_(?:MPF|SPF)\b", "%_N_..._MPF program header (Sinumerik)"),
           (r"^\s*;\s*\$PATH\s*=", ";$PATH= program header (Sinumerik)"),
           (r"(?i)^\s*(?:N\d+\s*)?DEF\s+(?:REAL|INT|BOOL|CHAR|STRING|AXIS|FRAME)\b",
            "DEF variable definition (Sinumerik)"),
           (r"(?i)^\s*(?:N\d+\s*)?.*\b(?:MSG\s*\(|T\s*=\s*\"|CR\s*=|=\s*(?:AC|IC)\s*\(|"
            r"(?:A?TRANS|A?ROT|MCALL|CYCLE\d+|POCKET\d|SLOT\d|TRAORI|G64\d|SOFT|BRISK|FFWON)\b)",
            "Sinumerik 840D syntax")),
    refused=(
        (r"(?i)\bPOCKET([1-4])\b", "POCKET{0} (pocket milling cycle)", _SINU_WHAT_INSTEAD),
        (r"(?i)\bSLOT([12])\b", "SLOT{0} (slot milling cycle)", _SINU_WHAT_INSTEAD),
        (r"(?i)\bLONGHOLE\b", "LONGHOLE (elongated holes cycle)", _SINU_WHAT_INSTEAD),
        (r"(?i)\bCYCLE(6[1-9]|7[0-2])\b", "CYCLE{0} (contour/face milling cycle)", _SINU_WHAT_INSTEAD),
        (r"(?i)\bCYCLE(7[6-9]|899|90)\b", "CYCLE{0} (milling cycle)", _SINU_WHAT_INSTEAD),
        (r"(?i)\bTRAORI\b", "TRAORI (5-axis transformation)",
         "post the program for 3 axes (X, Y, Z with fixed rotary positions): postproc corrects X, Y, Z"),
        (r"(?i)\bCYCLE800\b", "CYCLE800 (swivel plane)",
         "post the swivelled-plane moves in the machine's X, Y, Z (without CYCLE800)"),
        (r"(?i)\bCYCLE(84|840)\b", "CYCLE{0} (tapping cycle: its feed along Z is tied to the spindle's turns at "
                                   "the thread's pitch, so it cannot be written as corrected G1 moves)",
         "take the tapping out into a program of its own: postproc does not correct spindle-synchronised "
         "tapping"),
        (r"(?i)\b(A?ROTS|CROTS)\b", "{0} (frame rotation by solid angles)",
         "post the program in the work coordinates the frame gives (ROT/AROT about Z is read)"),
        (r"(?i)(?<![A-Z_])(?:IF|ELSE|WHILE|LOOP|FOR|REPEATB?|GOTOF|GOTOB|GOTOC|GOTO|ENDIF|ENDWHILE|ENDLOOP|ENDFOR"
         r"|UNTIL|CASE)\b"
         r"|^\s*(?:N\d+\s+)?[A-Za-z_]\w*:(?!=)", _SINU_CONTROL, "post the program flat (loops written out)"),
        (r"(?i)\b(?:PROC|CALL|PCALL|EXTCALL|EXTERN)\b|^\s*(?:N\d+\s*)?L\d+\b", _SINU_SUB,
         "give the subprogram's directory with --subroutine-path, or write its moves in the main program"),
        (r"(?i)\bTURN\s*=", "TURN= helix turns", "post the helix as its arcs"),
    ))

DIALECT_NAMES = ("generic", "linuxcnc", "fanuc", "haas", "grbl", "mach3", "fadal", "okuma", "sinumerik",
                 "fanuc-lathe")


def get(name: str | Dialect) -> Dialect:
    """The dialect called ``name`` (case-insensitive); a Dialect is returned as is."""
    if isinstance(name, Dialect):
        return name
    d = DIALECTS.get(str(name).strip().lower())
    if d is None:
        raise PostprocError(f"unknown dialect {name!r}", hint=f"use one of {', '.join(DIALECT_NAMES)}")
    return d


def comments_of(body: str) -> Iterator[tuple[int, str, str]]:
    """Yield ``(start, text, kind)`` for each comment of a line without its ending; kind is
    ``"("``, ``";"``, ``"nested"`` (a "(" inside a comment) or ``"unclosed"``."""
    i, n = 0, len(body)
    while i < n:
        c = body[i]
        if c == "(":
            j = body.find(")", i + 1)
            if j < 0:
                yield i, body[i + 1:], "unclosed"
                return
            inner = body[i + 1:j]
            if "(" in inner:
                yield i + 1 + inner.index("("), inner, "nested"
            yield i, inner, "("
            i = j + 1
            continue
        if c == ";":
            yield i, body[i + 1:], ";"
            return
        i += 1


class _Where(TypedDict):
    """The place of an output line, passed to each error about it."""

    path: str | None
    lineno: int | None


def check_output_line(d: str | Dialect, line: str, path: str | None = None, lineno: int | None = None) -> None:
    """Raise a PostprocError when controller ``d`` would refuse ``line`` (with or without its ending)."""
    d = get(d)
    body = line.rstrip("\n")
    count = len(body.encode("utf-8", errors="surrogateescape"))  # a carriage return counts
    if body.endswith("\r"):
        body = body[:-1]
    where: _Where = {"path": path, "lineno": lineno}
    if count > d.max_line_chars:
        raise PostprocError(
            f"line of {count} characters is longer than {d.title} reads ({d.max_line_chars})", col=d.max_line_chars + 1,
            hint="shorten the comment on this line" if "(" in body or ";" in body else
            f"this line cannot be written for --dialect {d.name}", **where)
    _check_characters(d, body, where)
    if "(" not in body and ";" not in body and ")" not in body:  # no comment: the common line
        if d.max_word_chars is not None and len(body) > d.max_word_chars:
            _check_words(d, d.max_word_chars, body, [(0, len(body))], where)
        return
    words = _check_comments(d, body, where)
    if d.max_word_chars is not None:
        _check_words(d, d.max_word_chars, body, words, where)


def _check_characters(d: Dialect, body: str, where: _Where) -> None:
    """Refuse the first character that ``d`` does not read: non-ISO, or lower case."""
    if d.ascii_only and not (body.isascii() and body.replace("\t", " ").isprintable()):
        for k, c in enumerate(body):
            if not (" " <= c <= "~" or c == "\t"):
                raise PostprocError(f"character {c!r} is not in the ISO code {d.title} reads", col=k + 1,
                                    hint="use ASCII letters, digits and punctuation only", **where)
    if d.uppercase_only and body.upper() != body:
        for k, c in enumerate(body):
            if c.isalpha() and c.islower():
                raise PostprocError(f"lower-case {c!r}: {d.title} reads upper-case letters only", col=k + 1,
                                    hint="write the program in upper case", **where)


def _check_comments(d: Dialect, body: str, where: _Where) -> list[tuple[int, int]]:
    """Refuse the first comment of ``body`` that ``d`` does not read; return the
    ``(start, end)`` spans of the text outside the comments."""
    words: list[tuple[int, int]] = []
    pos = 0
    for start, text, kind in comments_of(body):
        if kind in ("(", "unclosed", ";"):
            words.append((pos, start))
        if kind == "unclosed":
            raise PostprocError(f"comment opened here is not closed on its line, which {d.title} refuses",
                                col=start + 1, hint="close the comment with ')'", **where)
        if kind == "nested":
            raise PostprocError(f"'(' inside a comment: {d.title} reads nested comments as {d.nested_comments}",
                                col=start + 1, hint="remove the inner parenthesis", **where)
        if kind == ";":
            if not d.semicolon_comments:
                raise PostprocError(f"';' comment: {d.title} does not read ';' as a comment", col=start + 1,
                                    hint="write the comment in parentheses", **where)
            return words
        bad = [c for c in text if c in d.comment_forbidden]
        if bad:
            k = start + 1 + text.index(bad[0])
            raise PostprocError(f"{bad[0]!r} inside a comment, which {d.title} refuses", col=k + 1,
                                hint="remove it from the comment", **where)
        pos = start + len(text) + 2
    words.append((pos, len(body)))
    return words


def _check_words(d: Dialect, max_word_chars: int, body: str, words: list[tuple[int, int]], where: _Where) -> None:
    """Grbl keeps a line's words without blanks and comments in a buffer of its own
    (``max_word_chars``: ``d.max_word_chars``, which the caller has checked is set)."""
    cols = [k for a, b in words for k in range(a, b) if body[k] > " "]
    if len(cols) > max_word_chars:
        raise PostprocError(f"{len(cols)} characters of words on one line, more than {d.title} holds "
                            f"({max_word_chars})", col=cols[max_word_chars] + 1, hint="split the block",
                            **where)
