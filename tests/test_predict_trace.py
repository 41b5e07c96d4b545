"""Cutting edges, the trace r_s(t, p) = M(t) r_e(p), formula (4), cusps and runout (seed 002)."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from postproc.predict import tools
from postproc.predict.chain import chain_from_dict
from postproc.predict.operation import load_chain
from postproc.predict.trace import (
    SECONDS_PER_MINUTE,
    cutting_time_scale,
    envelope,
    facing_times,
    flank_surface,
    raster_section,
    runout_element,
    trace_points,
    window_times,
    with_runout,
)

SAMPLES = Path(__file__).parents[1] / "samples" / "predict"


@pytest.fixture(scope="module")
def mill():
    return load_chain(SAMPLES / "mill3.machine.json")


def cusp(radius, feed):
    return radius - np.sqrt(radius**2 - (feed / 2) ** 2)


def test_edges_follow_the_seed_formulas():
    p = np.array([0.0, 0.25, 0.5])
    cyl = tools.cylindrical_edge(p, 5.0, 1.0)
    assert_allclose(cyl, [[2.5, 0, 0], [0, 2.5, 0.25], [-2.5, 0, 0.5]], atol=1e-15)
    con = tools.conical_edge(p, 4.0, 6.0, 1.0, 1.0)  # radius 2 at the tip, 3 at p = L_c = 1
    assert_allclose(np.linalg.norm(con[:, :2], axis=1), [2.0, 2.25, 2.5])
    ball = tools.ball_edge(np.array([0.0, 1.0, 5.0]), 10.0, 4.0)
    assert_allclose(np.linalg.norm(ball - [0, 0, 5], axis=1)[1:], [5, 5])  # on the sphere about z = d/2
    assert_allclose(ball[0], [0, 0, 0], atol=1e-15)  # the tip
    bore = tools.boring_edge(np.array([0.0, 2.0]), 0.0, np.pi / 2, tip=(0, 25, 0))
    assert_allclose(bore, [[0, 25, 0], [-2, 25, 0]], atol=1e-15)  # plan angle 90 deg: edge along -x


def test_formula4_skips_the_air_between_cutting_windows():
    # t_m = 1, one revolution = 10: t in [0.5, 1.5) is window 0, [1.5, 2.5) window 1,
    # [2.5, 3.5) window 2; window k is moved k (10 - 1) later, [-0.5, 0.5) is window -1
    tau = cutting_time_scale(np.array([0.4, 1.0, 2.0, 3.0, 3.4]), 0.0, 0.1, 1.0)
    assert_allclose(tau, [0.4 - 9.0, 1.0, 11.0, 21.0, 21.4])
    # the helix correction t0 moves the windows earlier
    assert_allclose(cutting_time_scale(np.array([0.3]), 0.2, 0.1, 1.0), [0.3])


def test_window_centres_are_where_the_edge_faces_the_wall(mill):
    cutter = tools.Cutter("cylindrical", 5.0, 1.0, 5.0)
    rpm = 50000.0
    p = np.linspace(0, 5, 7)
    t_face = facing_times(cutter.helix_angle_rad(p), -np.pi / 2, rpm, "cw")
    t = window_times(t_face, rpm / SECONDS_PER_MINUTE, 1e-7, windows=4, samples=1)  # (4, 1, 7)
    assert_allclose(np.diff(t[:, 0, :], axis=0), SECONDS_PER_MINUTE / rpm, rtol=1e-9)
    pts = trace_points(mill, cutter.edge(p), {"t": t, "X": 0.0, "Y": 0.0, "Z": 0.0, "rpm": rpm})
    assert_allclose(pts[..., 0], 0.0, atol=1e-9)  # straight towards -y
    assert_allclose(pts[..., 1], -2.5, atol=1e-9)


def test_envelope_keeps_the_deepest_pass():
    u = np.array([[0.0, 1.0, 2.0], [1.0, 2.0, 3.0]])
    depth = np.array([[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]])
    assert_allclose(envelope(u, depth, [0.5, 1.5, 2.5, 4.0]), [0.5, 1.0, 1.0, -np.inf])


def test_flank_cusp_of_the_seed_example_matches_the_circle_formula(mill):
    # 5 mm cutter, 1 mm pitch, 50 000 rpm, 50 mm/min: feed per tooth 1 um, cusp 0.05 nm
    cutter = tools.Cutter("cylindrical", 5.0, 1.0, 5.0)
    s = flank_surface(mill, cutter, rpm=50000, feed_mm_min=50, heights_mm=np.linspace(0, 1, 5), windows=12)
    assert s.feed_per_edge_mm == pytest.approx(1e-3)
    assert s.t_m_s == pytest.approx(1e-3 / (np.pi * 5 * 50000 / 60))
    # circles against the trochoid: up to 2 f / (2 pi R) = 1.3e-4 relative (see below),
    # plus the interpolation of the sampled arcs
    assert_allclose(s.cusp_mm, cusp(2.5, 1e-3), rtol=1e-3)
    assert np.min(s.excess_mm) == pytest.approx(0.0, abs=1e-12)


def test_flank_cusp_with_a_coarse_feed_and_two_flutes(mill):
    cutter = tools.Cutter("cylindrical", 10.0, 30.0, 10.0, flutes=2)
    s = flank_surface(mill, cutter, rpm=1000, feed_mm_min=100, heights_mm=[0.0, 3.0], windows=10)
    assert s.feed_per_edge_mm == pytest.approx(0.05)
    # trochoid against circles: its radius of curvature at the wall is R (1 - f / (2 pi R))^2,
    # so the cusp is larger by up to 2 f / (2 pi R) = 3.2e-3
    assert_allclose(s.cusp_mm, cusp(5.0, 0.05), rtol=2 * 0.05 / (2 * np.pi * 5.0))
    assert np.all(s.cusp_mm >= cusp(5.0, 0.05))
    # the cusps repeat every feed per tooth along the wall
    prof = s.excess_mm[0]
    peaks = s.u_mm[1:-1][(prof[1:-1] > prof[:-2]) & (prof[1:-1] >= prof[2:]) & (prof[1:-1] > 0.5 * prof.max())]
    assert_allclose(np.diff(peaks), 0.05, rtol=1e-2)


def test_ball_end_scallop_between_raster_passes():
    # ball d = 10 at stepover 0.5 mm: scallop = R - sqrt(R^2 - (a/2)^2) = 6.254 um
    d, a, rpm = 10.0, 0.5, 6000.0
    ch = chain_from_dict({"format": "postproc chain", "modules": [
        {"name": "Y", "elements": [{"linear": {"axis": "y", "var": "Y"}}]},
        {"name": "spindle", "elements": [{"spindle": {"axis": "z", "rpm": "rpm", "var": "t"}}]},
    ]})
    cutter = tools.Cutter("ball", d, 20.0)
    p = d / 2 * tools.ball_edge_parameter(np.linspace(0, np.pi / 2, 3001))
    # the section points: each edge point where it faces +y or -y lies in the plane x = 0
    t = facing_times(cutter.helix_angle_rad(p), np.pi / 2, rpm, "cw")
    pts = trace_points(ch, cutter.edge(p), {"Y": 0.0, "t": t, "rpm": rpm})
    assert_allclose(pts[:, 0], 0.0, atol=1e-9)
    assert_allclose(np.hypot(pts[:, 1], pts[:, 2] - d / 2), d / 2)  # on the ball
    u, floor = raster_section(ch, cutter, rpm=rpm, stepover_mm=a, passes=5, samples=3001)
    assert np.min(floor) == pytest.approx(0.0, abs=1e-12)
    assert np.max(floor) == pytest.approx(cusp(d / 2, a), rel=1e-4)
    assert u[np.argmax(floor)] % a == pytest.approx(a / 2, abs=2e-3)
    # half the stepover, a quarter of the scallop
    _, finer = raster_section(ch, cutter, rpm=rpm, stepover_mm=a / 2, passes=5, samples=3001)
    assert np.max(finer) == pytest.approx(cusp(d / 2, a / 2), rel=1e-4)


def test_runout_element_frequency_is_once_per_spindle_revolution():
    # z flutes are modelled as one edge at z n; omega = 2 pi (z n) / z = 2 pi n
    el = runout_element(1e-4, edge_rpm=3 * 1000.0, flutes=3)
    sine = el.body["beta"]["sine"]
    assert sine["omega"] == pytest.approx(2 * np.pi * 1000.0 / 60.0)
    m = el.matrix({"t": np.array([0.015])})  # a quarter of a revolution at 1000 rpm
    assert_allclose(m[0, 0, 2], 1e-4)  # M_f: +A sin(omega t) at (1, 3), -A sin at (3, 1)
    assert_allclose(m[0, 2, 0], -1e-4)


def test_runout_of_a_single_flute_cutter_makes_the_wall_wavy_in_height(mill):
    # beta = A sin(omega t) about the turning y axis: at the instant the point at height p
    # faces the wall (-y) it cuts deeper by A p cos^2(2 pi p / p_e) (the edge turns cw).
    amp = 1e-4
    cutter = tools.Cutter("cylindrical", 5.0, 1.0, 5.0)
    p = np.linspace(0, 2, 17)
    kw = {"rpm": 50000, "feed_mm_min": 50, "heights_mm": p, "windows": 8}
    plain = flank_surface(mill, cutter, **kw)
    wavy = flank_surface(with_runout(mill, amp, 50000, 1), cutter, **kw)
    expected = -amp * p * np.cos(2 * np.pi * p / 1.0) ** 2
    assert_allclose(wavy.excess_mm.mean(axis=1) - plain.excess_mm.mean(axis=1), expected, atol=1e-3 * amp)
    # every revolution is the same, so the cusps along the feed do not change
    assert_allclose(wavy.cusp_mm, plain.cusp_mm, rtol=1e-2)


def test_runout_of_a_two_flute_cutter_alternates_the_flutes(mill):
    amp, p = 1e-4, 1.0
    cutter = tools.Cutter("cylindrical", 5.0, 1.0, 5.0, flutes=2)
    kw = {"rpm": 25000, "feed_mm_min": 50, "heights_mm": [p], "windows": 12}
    plain = flank_surface(mill, cutter, **kw)
    alt = flank_surface(with_runout(mill, amp, 50000, 2, phase_rad=np.pi / 2), cutter, **kw)
    fz = plain.feed_per_edge_mm
    assert_allclose(plain.cusp_mm, cusp(2.5, fz), rtol=1e-3)
    # omega = 2 pi n_edge / z puts successive flutes half a runout period apart: at the
    # point p = 1 (facing the wall a quarter turn in, omega t = pi/4) one flute reaches
    # A p cos(pi/4) deeper, the other as much less and never touches the wall again:
    # the cusps are those of the feed per revolution, 2 f_z.
    assert_allclose(alt.cusp_mm, cusp(2.5, 2 * fz), rtol=1e-2)
    assert np.min(alt.excess_mm) == pytest.approx(-amp * p * np.cos(np.pi / 4), rel=1e-3)
