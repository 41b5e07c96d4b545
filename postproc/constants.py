"""Named tolerances, each with the reason for its value."""

# Inverse solvers stop when |F(q) - p*| is below this: a hundred times finer than the
# best machine-tool positioning resolution (0.1 um), so it never shows in a program.
SOLVER_TOL_MM = 1e-6
# A solver answer is accepted up to ten times its own stopping tolerance (float noise
# in the residual itself); still a thousand times below the default path tolerance.
# An engine whose solver stands for larger residuals says so in ``accept_residual_mm``
# (the parametric astatic solver: one grid step); the larger of the two applies.
SOLVER_ACCEPT_MM = 10 * SOLVER_TOL_MM

# Most iterations a converged solver may take before it reports failure. Newton on a
# smooth error field with corrections << 1 mm converges in 2-4; 50 means something is wrong.
SOLVER_MAX_ITER = 50

# Default bound on any single correction; a unit mistake (um read as mm) must not move
# a machine by millimetres.
DEFAULT_MAX_CORRECTION_MM = 1.0

# Default path tolerance between the emitted and the corrected ideal path.
DEFAULT_TOLERANCE_MM = 0.001

# Controller arc check: endpoint radii must agree within this absolute difference ...
ARC_RADIUS_ABS_MM = 0.002
# ... or this relative difference (LinuxCNC's rule: 0.002 mm or 0.1 %).
ARC_RADIUS_REL = 0.001

# Relative slack on calibrated-volume bounds so a point measured exactly at the edge and
# re-read from text with rounding is still inside.
VOLUME_EDGE_SLACK_MM = 1e-6

# Largest coordinate a calibrated volume may reach (100 m). The largest machine tools
# (gantry mills, ship-propeller lathes) travel some tens of metres; a volume beyond this
# is a unit mistake or a way of switching the outside-volume check off (1e308).
MAX_VOLUME_MM = 100_000.0

MM_PER_INCH = 25.4

# Closest two positions of an axis error table may be (mm). Interferometer tables are
# taken millimetres apart; positions a micrometre apart or closer are a typing or unit
# mistake, and the slope between them (error / spacing) is no machine's.
MIN_TABLE_SPACING_MM = 1e-3
