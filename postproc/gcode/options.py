"""What a correction run is given and what it reports: :class:`CorrectOptions` and
:class:`CorrectReport`, shared by the reader, the planner and the writer of the lane
(:mod:`postproc.gcode.pipeline`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from postproc.constants import DEFAULT_MAX_CORRECTION_MM, DEFAULT_TOLERANCE_MM, SOLVER_ACCEPT_MM
from postproc.gcode import cutter
from postproc.limits import Limits

# Output growth (lines out / lines in) above which the summary warns.
GROWTH_WARN = 5.0


@dataclass
class CorrectOptions:
    tolerance_mm: float = DEFAULT_TOLERANCE_MM
    decimals: int | None = None  # default 4 in mm, 5 in inch
    max_correction_mm: float = DEFAULT_MAX_CORRECTION_MM
    extrapolate: str = "refuse"  # refuse | clamp | linear
    force: bool = False
    added: list = field(default_factory=list)
    chunk_lines: int | None = None  # default: DEFAULT_CHUNK_LINES, or SEGMENTED_CHUNK_LINES with segmentation
    dialect: str = "generic"  # the controller the program is for: how it is read and written
    expand: bool = True  # flatten parameters, O-words, subprograms and macros (False: refuse them)
    subroutine_path: tuple = ()  # folders searched for o<name> call and M98 subprogram files
    # keep: a cycle stays a cycle (X/Y at the bottom, R and Z along the tool axis); expand: its
    # moves written out as G0/G1, each corrected; auto: kept where its tilt is within the
    # tolerance, else expanded with the rest of its series (to the next G80 or other motion)
    cycles: str = "auto"
    bulk_lane: bool = True  # runs of plain lines read and written per chunk (same output; off for comparison)
    bulk_plan: bool = True  # moves that stay one line or one exact arc settled in bulk (off: sample by sample)
    processes: int = 1  # more: a large program file is cut into parts corrected in that many (postproc.gcode.split)
    limits: Limits = field(default_factory=Limits)  # iterations, output lines, helix turns (postproc.limits)


@dataclass
class CorrectReport:
    lines_in: int = 0
    lines_out: int = 0
    moves: int = 0
    words_changed: int = 0
    lines_changed: int = 0
    lines_inserted: int = 0
    arcs_kept: int = 0
    arcs_linearised: int = 0
    extrapolated_points: int = 0
    max_correction_mm: float = 0.0
    g54_assumed_zero: bool = False
    solver: str = ""  # the engine's inverse solver when it names one (parametric: newton | astatic)
    accept_residual_mm: float = SOLVER_ACCEPT_MM  # largest inverse residual accepted
    max_residual_mm: float = 0.0  # largest inverse residual met
    cycles_kept: int = 0
    splines_linearised: int = 0
    expanded: bool = False  # the program was expanded (subprograms, loops, parameters)
    cycles_expanded: int = 0
    arcs_split: int = 0  # arcs emitted as several exact arcs
    takeups: int = 0  # lines inserted to take up a reversal (backlash)
    header_lines: int = 0  # the postproc header's lines (counted in lines_out)
    cutter: cutter.Bound | None = None  # moves under cutter radius compensation and their bound

    @property
    def growth(self) -> float:
        """The program's own lines out / lines in: the header, which carries the setup
        (one line per few tool lengths), is not the program growing."""
        return (self.lines_out - self.header_lines) / self.lines_in if self.lines_in else 1.0
