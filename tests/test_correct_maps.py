"""Measured-map corrections added after the engine inverse (``added`` and ``--map``)."""

import sys
import types
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from postproc.cli import main
from postproc.engine.static import StaticEngine
from postproc.gcode import emit
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
VOLUME = [[0.0, 0.0, 0.0], [315.0, 315.0, 315.0]]


class ZRamp:
    """Fake map: adds 0.01 mm per 100 mm of X to Z (and records what it was asked)."""

    name = "zramp"

    def __init__(self):
        self.calls = []

    def delta(self, p_mm, context):
        self.calls.append((np.array(p_mm), dict(context)))
        out = np.zeros((len(p_mm), 3))
        out[:, 2] = 1e-4 * np.asarray(p_mm)[:, 0]
        return out


def test_added_correction_is_applied_after_the_engine_and_splits_moves():
    eng = StaticEngine(np.eye(3), [0.02, 0.0, 0.0], VOLUME)
    text = "G21 G90\nG0 X0 Y10 Z10\nG1 X200 F100\n"
    ramp = ZRamp()
    out, rep = correct_text(text, eng, Setup(), CorrectOptions(added=[ramp]))
    pp = program_path(out, Setup(), max_step_mm=1.0)
    q = pp.points_mm
    # engine: X shifted by -0.02; map: Z raised by 1e-4 * X (evaluated at the nominal point)
    np.testing.assert_allclose(q[-1], [199.98, 10.0, 10.02], atol=1e-4)
    assert "dirx" in ramp.calls[0][1]
    assert "lineno" in ramp.calls[0][1]
    assert "(POSTPROC MAP ZRAMP)" in "".join(emit.split_header(out)[0])
    # a map is not affine in general, so straight moves are checked and split if needed
    assert rep.lines_inserted == 0  # this ramp is linear: nothing to split


def test_cli_map_option_loads_through_mirror_maps(tmp_path, monkeypatch):
    fake = types.ModuleType("postproc.mirror.maps")
    loaded = []

    def load_map(path):
        loaded.append(path)
        return ZRamp()

    fake.load_map = load_map
    monkeypatch.setitem(sys.modules, "postproc.mirror.maps", fake)
    mapfile = tmp_path / "ramp.csv"
    mapfile.write_text("# a map\n")
    out = tmp_path / "o.nc"
    r = CliRunner().invoke(main, ["correct", str(ROOT / "samples" / "pocket.nc"), "-c",
                                  str(ROOT / "tests" / "cases" / "demo_static.json"), "--map", str(mapfile),
                                  "-o", str(out)], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert loaded == [str(mapfile)]
    plain = tmp_path / "plain.nc"
    CliRunner().invoke(main, ["correct", str(ROOT / "samples" / "pocket.nc"), "-c",
                              str(ROOT / "tests" / "cases" / "demo_static.json"), "-o", str(plain)])
    a = program_path(str(out), Setup()).points_mm[-1]
    b = program_path(str(plain), Setup()).points_mm[-1]
    np.testing.assert_allclose(a - b, [0.0, 0.0, 1e-4 * b[0]], atol=2e-4)
