"""Effects at correction time: the pipeline compensates backlash from the program's
move directions and thermal drift at a given --context value, or refuses."""

import re

import numpy as np
import pytest

from postproc.effects import compose, get_effect
from postproc.engine.identity import IdentityEngine
from postproc.errors import MissingSetupError
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import correct_text

VOLUME = [[-10, -10, -10], [310, 310, 310]]
# X goes out to 200 (approach +1), back to 100 (approach -1), out to 150 (+1).
PROGRAM = "G21 G90 G54\nG0 X0 Y0 Z0\nG1 X200 F500\nG1 X100\nG1 X150\nM30\n"
B_MM = 0.02


def xs(text: str) -> list[float]:
    return [float(m) for m in re.findall(r"^G1 X([-\d.]+)", text, flags=re.M)]


def test_backlash_is_compensated_from_move_directions():
    # lost motion (b < 0): each target is commanded b/2 against its approach direction,
    # and each reversal (the first feed move from the unknown direction too) is taken up
    # where it happens, before the move, in the new direction, as a controller's backlash
    # compensation does
    eng = compose(IdentityEngine(VOLUME), [get_effect("backlash:X", params={"b_mm": -B_MM}).to_dict()])
    out, _ = correct_text(PROGRAM, eng, Setup(offsets={"G54": (0, 0, 0)}))
    assert xs(out) == pytest.approx([B_MM / 2, 200 + B_MM / 2, 200 - B_MM / 2, 100 - B_MM / 2,
                                     100 + B_MM / 2, 150 + B_MM / 2], abs=1e-4)


def test_an_axis_that_runs_ahead_reverses_without_a_take_up():
    # b > 0: a take-up would move on in the old direction and overshoot by b; none is
    # written, the first move back reverses X and its target is commanded for the new
    # direction (the table jumps back by b along the move)
    eng = compose(IdentityEngine(VOLUME), [get_effect("backlash:X", params={"b_mm": B_MM}).to_dict()])
    out, rep = correct_text(PROGRAM, eng, Setup(offsets={"G54": (0, 0, 0)}))
    assert xs(out) == pytest.approx([200 - B_MM / 2, 100 + B_MM / 2, 150 - B_MM / 2], abs=1e-4)
    assert rep.takeups == 0


def test_thermal_needs_context_at_correction_time():
    eff = get_effect("thermal:t", config={"tau_s": 1800.0}, params={"dx_mm": 0.03})
    eng = compose(IdentityEngine(VOLUME), [eff.to_dict()])
    with pytest.raises(MissingSetupError, match=r"--context t=") as exc:
        correct_text(PROGRAM, eng, Setup(offsets={"G54": (0, 0, 0)}))
    assert "thermal:t" in str(exc.value)
    out, _ = correct_text(PROGRAM, eng, Setup(offsets={"G54": (0, 0, 0)}, context={"t": 3600.0}))
    drift = 0.03 * (1 - np.exp(-2.0))
    assert xs(out) == pytest.approx([200 - drift, 100 - drift, 150 - drift], abs=1e-4)
