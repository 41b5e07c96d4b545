"""The fit of a move cut into many pieces (postproc.gcode.arcfit.MoveFit) costs in
proportion to its pieces: a helix of many turns, along which s500_parametric's correction
varies, is measured at a cost per turn that does not grow with its turns, and is written
as it was pinned (sha256 of the outputs). segment.off_every_circle, which refuses the
tries far beyond the farthest sample one arc reaches, never refuses points near a circle
through the start, and refuses only tries the full measure refuses too."""

from __future__ import annotations

import hashlib
import math
import re
import sys

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import PARAMETRIC, ROOT

from postproc.cli import main
from postproc.gcode import arcfit, fitcore
from postproc.gcode.segment import ArcPiece, off_every_circle, off_every_helix

sys.path.insert(0, str(ROOT / "benchmarks"))
from helix_time import OFFSET, helix_program  # noqa: E402

_VERSION_LINE = re.compile(r"^(\s*\(POSTPROC )\S+( CORRECTED\))", re.MULTILINE | re.IGNORECASE)

# sha256 of the corrected helices (version word written as VERSION), as pinned
PINNED = {
    5: "42a9ede3077b9e84af6a9c9d057aa7a08c8759c7e79db03b988cc4b81a987d92",
    10: "edf53763e67f608e3803f9ea9f117daedfb4633f402ee2b5e439fc1eff9a0733",
    20: "16cfa5c514740ad28fef513d597eba82976d995d0afc94cb5c68e6e0865b0f5d",
    40: "92af5a4e9b410698377b9fcb943a2bf5b6eead0438a026b913c55933a646d774",
}

# a helix of radius 2 mm descending 0.5 mm a turn: its pieces (about two a turn) fail along
# its axis, not in its plane
SMALL = {
    10: "c3537739bf037af5c2c89f5f339867ab53f78e53622a3b598c05403e9c370bcf",
    80: "e2f951c02e3e1f8ca987ed7ae8df1bd6a652ce92167c73be854049e8e9766734",
}


def _small_helix(turns: int) -> str:
    return f"G21 G90 G17\nG0 X2 Y0 Z0\nG2 X2 Y0 I-2 J0 Z-{turns / 2:g} P{turns} F500\nM2\n"


def _correct(tmp_path, turns: int, program=helix_program) -> str:
    src = tmp_path / f"helix{turns}.ngc"
    src.write_text(program(turns))
    out = tmp_path / f"helix{turns}_out.ngc"
    res = CliRunner().invoke(main, ["correct", str(src), "-c", str(PARAMETRIC), "--offset", OFFSET,
                                    "-j", "1", "-o", str(out)])
    assert res.exit_code == 0, res.output
    return out.read_text()


class _Count:
    """Samples measured by the fit: rows of each deviation measure (per centre measured),
    of each centre fit and of each chord measure."""

    def __init__(self, monkeypatch) -> None:
        self.n = 0
        count = self
        centre, chord, arc_try = arcfit.bisector_centre, fitcore.chord_deviation, fitcore.ArcTry

        class _Try:
            def __init__(self, *args) -> None:
                self.tr = arc_try(*args)
                self.s1, self.s2, self.e1, self.e2 = self.tr.s1, self.tr.s2, self.tr.e1, self.tr.e2

            def measure(self, *args, **kwargs):
                found = self.tr.measure(*args, **kwargs)
                count.n += len(self.tr.us) * len(found.idx)
                return found

        def _centre(S2, E2, P2, c0):
            self.n += len(P2)
            return centre(S2, E2, P2, c0)

        def _chord(S, E, xs, ys, zs):
            self.n += len(xs)
            return chord(S, E, xs, ys, zs)

        monkeypatch.setattr(fitcore, "ArcTry", _Try)
        monkeypatch.setattr(arcfit, "bisector_centre", _centre)
        monkeypatch.setattr(fitcore, "chord_deviation", _chord)


def _per_turn(tmp_path, monkeypatch, pinned, program=helix_program) -> dict[int, float]:
    """Samples measured per turn, per number of turns; each output checked against its sum."""
    count = _Count(monkeypatch)
    per_turn = {}
    for turns in sorted(pinned):
        count.n = 0
        text = _correct(tmp_path, turns, program)
        per_turn[turns] = count.n / turns
        digest = hashlib.sha256(_VERSION_LINE.sub(r"\1VERSION\2", text).encode()).hexdigest()
        assert digest == pinned[turns], turns
    return per_turn


def test_a_helix_costs_in_proportion_to_its_turns_and_is_written_as_pinned(tmp_path, monkeypatch):
    per_turn = _per_turn(tmp_path, monkeypatch, PINNED)
    assert per_turn[40] <= 1.3 * per_turn[5], per_turn
    assert per_turn[20] <= 1.3 * per_turn[5], per_turn


def test_a_small_helix_costs_in_proportion_to_its_turns_and_is_written_as_pinned(tmp_path, monkeypatch):
    per_turn = _per_turn(tmp_path, monkeypatch, SMALL, _small_helix)
    assert per_turn[80] <= 1.3 * per_turn[10], per_turn


def _ellipse(rng, k, a, b, turns=1.0):
    t = np.sort(rng.uniform(0.0, turns * 2 * math.pi, k))
    return np.column_stack([a * np.cos(t), b * np.sin(t)]), t


@pytest.mark.parametrize("seed", range(40))
def test_points_near_a_circle_through_the_start_are_never_refused(seed):
    rng = np.random.default_rng(seed)
    bound = 10.0 ** rng.uniform(-5, -1)
    r = 10.0 ** rng.uniform(-2, 3)
    c = rng.uniform(-500, 500, 2)
    t0 = rng.uniform(0, 2 * math.pi)
    S2 = c + r * np.array([math.cos(t0), math.sin(t0)])
    k = int(rng.integers(4, 300))
    t = t0 + rng.uniform(0.0, rng.uniform(0.1, 6 * math.pi), k)
    rho = r + rng.uniform(-1.0, 1.0, k) * bound
    # the worst points on the edge of the band
    rho[rng.integers(0, k, 3)] = r + bound * rng.choice([-1.0, 1.0], 3)
    P2 = c + rho[:, None] * np.column_stack([np.cos(t), np.sin(t)])
    assert not off_every_circle(S2, P2, bound)


def test_an_ellipse_is_off_every_circle_by_a_share_of_its_axes_difference():
    rng = np.random.default_rng(1)
    P2, _ = _ellipse(rng, 200, 20.01, 19.99)
    S2 = np.array([20.01, 0.0])
    # about a 0.01 radial departure from the best circle
    assert off_every_circle(S2, P2, 0.001)
    assert not off_every_circle(S2, P2, 0.02)
    # too few points, or all on one line: cannot tell
    assert not off_every_circle(S2, P2[:3], 0.001)
    line = np.column_stack([np.linspace(1, 2, 10), np.zeros(10)])
    assert not off_every_circle(np.zeros(2), line, 0.001)


def _helix(rng, k, bound, budget, bulge=0.0):
    """A piece of a helix (a random centre, radius, start, sweep of half a turn to twenty
    turns, either way) through k samples strayed by up to ``bound`` from its radius and
    ``budget`` along its axis, plus ``bulge`` sin(pi frac) along its axis."""
    r = 10.0 ** rng.uniform(0, 2)
    c = rng.uniform(-200, 200, 2)
    t0 = rng.uniform(0, 2 * math.pi)
    clockwise = bool(rng.integers(0, 2))
    sweep = rng.uniform(math.pi, 40 * math.pi) * (-1.0 if clockwise else 1.0)
    z0, dz = rng.uniform(-100, 100), rng.uniform(-50, 50)
    frac = np.sort(rng.uniform(0, 1, k))
    frac[0], frac[-1] = 0.0, 1.0
    t = t0 + sweep * frac
    rho = r + rng.uniform(-1, 1, k) * bound
    z = z0 + dz * frac + rng.uniform(-1, 1, k) * budget + bulge * np.sin(math.pi * frac)
    Q = np.column_stack([c[0] + rho * np.cos(t), c[1] + rho * np.sin(t), z])
    S = np.array([c[0] + r * math.cos(t0), c[1] + r * math.sin(t0), z0])
    E = np.array([c[0] + r * math.cos(t[-1]), c[1] + r * math.sin(t[-1]), z0 + dz])
    return ArcPiece(S, E, (0, 1, 2), clockwise, sweep, Q, frac)


@pytest.mark.parametrize("seed", range(40))
def test_samples_near_a_helix_from_the_start_to_the_end_are_never_refused(seed):
    rng = np.random.default_rng(seed)
    bound, budget = 10.0 ** rng.uniform(-4, -2), 10.0 ** rng.uniform(-4, -2)
    piece = _helix(rng, int(rng.integers(4, 200)), 0.9 * bound, 0.9 * budget)
    assert not off_every_helix(piece, bound, budget)


def test_a_helix_whose_height_bulges_is_off_every_helix():
    rng = np.random.default_rng(3)
    refused = sum(off_every_helix(_helix(rng, 128, 0.0009, 0.0009, bulge=0.01), 0.001, 0.001)
                  for _ in range(20))
    assert refused >= 15
    assert not off_every_helix(_helix(rng, 128, 0.0009, 0.0009, bulge=0.0001), 0.001, 0.001)


def test_a_try_refused_unmeasured_is_refused_by_the_full_measure(tmp_path, monkeypatch):
    """Every try that MoveFit._off_every_arc refuses on the helix is refused by the full
    measure as well (the arc's tries, all its centres and forms)."""
    refused = []
    off = arcfit.MoveFit._off_every_arc
    exact = arcfit.MoveFit._exact_arc

    def _off(self, S, E, Qp, frac, nsw, keep):
        verdict = off(self, S, E, Qp, frac, nsw, keep)
        refused.append(verdict)
        return verdict

    def _exact_arc(self, smp, lo, hi, S_, E_, offset, flat, may_keep):
        spec = exact(self, smp, lo, hi, S_, E_, offset, flat, may_keep)
        if refused and refused[-1]:
            refused[-1] = False
            monkeypatch.setattr(arcfit.MoveFit, "_off_every_arc", lambda *a: False)
            try:
                assert exact(self, smp, lo, hi, S_, E_, offset, flat, may_keep) is None
            finally:
                monkeypatch.setattr(arcfit.MoveFit, "_off_every_arc", _off)
            checked.append(hi - lo)
        return spec

    checked: list[int] = []
    monkeypatch.setattr(arcfit.MoveFit, "_off_every_arc", _off)
    monkeypatch.setattr(arcfit.MoveFit, "_exact_arc", _exact_arc)
    _correct(tmp_path, 3)
    assert len(checked) >= 10
    assert max(checked) > 2000
