"""The parametric engine's fast evaluation (stacked error tables, Newton reusing the
located points, vectorised 3 x 3 solves) against the straightforward evaluation it
replaced (tests/parametric_reference.py): the same bits, not merely close values."""

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from parametric_reference import ReferenceParametric

from postproc.calfile import load_calibration
from postproc.calibration.axis_tables import AXES, AxisTables
from postproc.constants import SOLVER_MAX_ITER, SOLVER_TOL_MM
from postproc.engine import parametric_errors, parametric_solvers
from postproc.engine.parametric import ParametricEngine
from postproc.simulate.s500 import synthetic_tables

CAL = "calibrations/s500_parametric.json"
# around the thresholds where the evaluation changes method (buckets, vectorised LU)
SIZES = (1, 2, 5, 47, 48, 63, 64, 65, 300, 2500)


def same_bits(a, b) -> bool:
    """Equal arrays to the last bit: NaN patterns and the signs of zeros included."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind != "f":
        return bool(np.array_equal(a, b))
    return bool(np.array_equal(np.ascontiguousarray(a).view(np.uint64), np.ascontiguousarray(b).view(np.uint64)))


@pytest.fixture(scope="module")
def s500():
    return load_calibration(Path(__file__).parents[1] / CAL).engine


def points(engine, n, rng, outside=True):
    """Random commanded points: inside the tables, on their knots, beyond their ends."""
    lo, hi = engine.volume_mm
    span = hi - lo
    q = rng.uniform(lo - 0.2 * span, hi + 0.2 * span, (n, 3)) if outside else rng.uniform(lo, hi, (n, 3))
    k = n // 4
    if k:
        # exactly on knots (s = 0, the last knot: the clipped interval) and the table ends
        for i, ax in enumerate(AXES):
            x = engine.tables.position_mm[ax]
            q[:k, i] = rng.choice(np.concatenate([x, [lo[i], hi[i]]]), k)
    return q


def tool_vectors(n, rng):
    r = np.column_stack([rng.uniform(-30, 30, n), rng.uniform(-30, 30, n), -rng.uniform(0, 200, n)])
    r[: n // 5] = 0.0
    return r


def assert_model_equal(engine, ref, rng):
    for n in SIZES:
        q = points(engine, n, rng)
        r = tool_vectors(n, rng)
        assert same_bits(engine.forward(q, r), ref.forward(q, r)), n
        for order in ("first", "second", "exact"):
            assert same_bits(engine.forward_order(q, r, order), ref.forward_order(q, r, order)), (n, order)
        for a, b in zip(engine.errors_at(q), ref.errors_at(q), strict=True):
            assert same_bits(a, b), n
        for a, b in zip(engine.error_derivatives(q), ref.error_derivatives(q), strict=True):
            assert same_bits(a, b), n
        assert same_bits(engine.jacobian(q, r), ref.jacobian(q, r)), n
        assert same_bits(engine.forward(q), ref.forward(q)), n  # no tool vector


def assert_inverse_equal(engine, ref, rng, sizes=SIZES):
    iterations = set()
    for n in sizes:
        p = points(engine, n, rng, outside=False)
        r = tool_vectors(n, rng)
        a = engine.inverse(p, r)
        b = ref.inverse(p, r, tol_mm=SOLVER_TOL_MM, max_iter=SOLVER_MAX_ITER)
        assert same_bits(a.q, b.q), n
        assert same_bits(a.residual_mm, b.residual_mm), n
        assert same_bits(a.iterations, b.iterations), n
        iterations.update(a.iterations.tolist())
    return iterations


@pytest.mark.parametrize("options", [
    {},
    {"extrapolate": "linear"},
    {"order": "second"},
    {"order": "second", "extrapolate": "linear"},
    {"order": "exact"},
    {"interpolation": "linear"},
    {"interpolation": "linear", "extrapolate": "linear", "order": "second"},
])
def test_s500_model_and_inverse_are_bit_identical(s500, options):
    engine = s500.with_options(**options)
    ref = ReferenceParametric(engine)
    rng = np.random.default_rng(11)
    assert_model_equal(engine, ref, rng)
    assert_inverse_equal(engine, ref, rng)


@pytest.mark.parametrize("seed", [0, 3])
def test_synthetic_tables_with_large_angles_iterate_unevenly_and_match(seed):
    """Angles scaled up: points need different numbers of Newton steps, so the solver's
    subsets of still-active points (not just whole arrays) are exercised."""
    tables, sq = synthetic_tables(seed)
    for order in ("first", "second"):
        engine = ParametricEngine(tables.scaled(angle_factor=30.0), sq, order=order, extrapolate="linear")
        ref = ReferenceParametric(engine)
        rng = np.random.default_rng(seed)
        assert_model_equal(engine, ref, rng)
        iterations = assert_inverse_equal(engine, ref, rng, sizes=(1, 64, 500, 2000))
        assert len(iterations) > 1


def test_irregular_knots_use_the_binary_search_and_match():
    """Knots far from uniform (no buckets) and of different counts per axis."""
    rng = np.random.default_rng(4)
    pos, err = {}, {}
    for i, ax in enumerate(AXES):
        n = 9 + 5 * i
        x = np.cumsum(np.concatenate([[0.0], rng.uniform(0.01, 1.0, n - 1) ** 3 * 80]))
        pos[ax] = x
        e = 2e-3 * np.sin(x[:, None] / 40.0 + rng.uniform(0, 6, 6)) + rng.normal(scale=2e-4, size=(n, 6))
        e[:, 3:] *= 1e-2
        err[ax] = e
    engine = ParametricEngine(AxisTables(pos, err))
    assert engine._stacked._buckets is None
    ref = ReferenceParametric(engine)
    assert_model_equal(engine, ref, rng)
    assert_inverse_equal(engine, ref, rng)


def test_buckets_locate_like_searchsorted(s500):
    st = s500._stacked
    assert st._buckets is not None
    rng = np.random.default_rng(8)
    lo, hi = s500.volume_mm
    q = rng.uniform(lo - 5, hi + 5, (5000, 3))
    x = s500.tables.position_mm["X"]
    q[:1000, 0] = rng.choice(x, 1000)
    q[1000:2000, 0] = np.nextafter(rng.choice(x, 1000), -np.inf)  # just below a knot
    q[2000:3000, 1] = np.nextafter(rng.choice(x, 1000), np.inf)
    fast = st.locate(q)
    slow = st.locate(q[:10])  # under BUCKET_MIN_POINTS: binary search
    assert q.shape[0] >= parametric_errors.BUCKET_MIN_POINTS > 10
    for a, ax in enumerate(AXES):
        xs = s500.tables.position_mm[ax]
        tc = np.clip(q[:, a], xs[0], xs[-1])
        want = np.clip(np.searchsorted(xs, tc, side="right") - 1, 0, len(xs) - 2) + st._gmin[a, 0]
        assert np.array_equal(fast.g[a], want)
        assert np.array_equal(slow.g[a], want[:10])


def test_not_finite_points_give_what_the_reference_gives(s500):
    ref = ReferenceParametric(s500)
    q = np.tile([100.0, 50.0, 20.0], (100, 1))
    q[3, 0], q[50, 1], q[70, 2] = np.nan, np.inf, -np.inf
    for n in (5, 100):
        with np.errstate(invalid="ignore"):
            assert same_bits(s500.forward(q[:n]), ref.forward(q[:n]))
            assert same_bits(s500.jacobian(q[:n]), ref.jacobian(q[:n]))


def test_not_contiguous_inputs_match(s500):
    ref = ReferenceParametric(s500)
    rng = np.random.default_rng(2)
    p = np.asfortranarray(points(s500, 400, rng, outside=False))
    r = np.asfortranarray(tool_vectors(400, rng))
    for pp, rr in ((p, r), (p[::2], r[::2]), (p, r[0])):
        a = s500.inverse(pp, rr)
        b = ref.inverse(pp, rr, tol_mm=SOLVER_TOL_MM, max_iter=SOLVER_MAX_ITER)
        assert same_bits(a.q, b.q)
        assert same_bits(a.residual_mm, b.residual_mm)
        assert same_bits(s500.forward(pp, rr), ref.forward(pp, rr))


def _avx2_fma() -> bool:
    """Whether this is an x86-64 CPU with AVX2 and FMA (OpenBLAS's Haswell kernels run)."""
    try:
        flags = next((row for row in Path("/proc/cpuinfo").read_text().splitlines() if row.startswith("flags")), "")
    except OSError:
        return False
    return {"avx2", "fma"} <= set(flags.split())


def _lapack_solve(J: np.ndarray, f: np.ndarray) -> np.ndarray:
    """LAPACK's solution of J x = f (numpy's ``solve``, dgesv). OpenBLAS picks its kernels
    by the CPU, and on one with AVX-512 (SkylakeX kernels) about a third of these systems
    come out different in the last bits; on an x86-64 CPU with AVX2 the solve runs in a
    child process with OpenBLAS held to its Haswell kernels (``OPENBLAS_CORETYPE``), the
    ones it runs on AVX2 machines, so that the reference is one on every such machine."""
    if not _avx2_fma():
        return np.linalg.solve(J, f[:, :, None])[:, :, 0]
    with tempfile.TemporaryDirectory() as tmp:
        np.save(f"{tmp}/J.npy", J)
        np.save(f"{tmp}/f.npy", f)
        code = ("import numpy as np, sys; t = sys.argv[1]; J, f = np.load(t + '/J.npy'), np.load(t + '/f.npy'); "
                "np.save(t + '/x.npy', np.linalg.solve(J, f[:, :, None])[:, :, 0])")
        subprocess.run([sys.executable, "-c", code, tmp], check=True,
                       env=dict(os.environ, OPENBLAS_CORETYPE="Haswell"))
        return np.load(f"{tmp}/x.npy")


def test_vectorised_lu_solves_like_lapack():
    rng = np.random.default_rng(6)
    n = 60_000
    J = np.eye(3) + rng.normal(scale=1e-3, size=(n, 3, 3))
    J[: n // 3] = rng.normal(size=(n // 3, 3, 3))  # pivoting on every column
    J[n // 3: n // 2] = rng.integers(-3, 4, (n // 2 - n // 3, 3, 3))  # ties between pivots
    f = rng.normal(scale=1e-2, size=(n, 3))
    keep = np.abs(np.linalg.det(J)) >= parametric_solvers.MIN_JACOBIAN_DET
    J, f = J[keep], f[keep]
    x, det = parametric_solvers._lu_solve_3x3(J, f)
    assert same_bits(x, _lapack_solve(J, f))
    np.testing.assert_allclose(np.abs(det), np.abs(np.linalg.det(J)), rtol=1e-12)
    # the (3, 3, N) layout the engine hands over gives the same
    Jt = np.ascontiguousarray(J.transpose(1, 2, 0)).transpose(2, 0, 1)
    assert same_bits(parametric_solvers._lu_solve_3x3(Jt, f)[0], x)
    bad = J.copy()
    bad[5, 1, 1] = np.nan
    assert parametric_solvers._lu_solve_3x3(bad, f) is None


def test_solve_falls_back_to_lapack_and_names_the_singular_point():
    rng = np.random.default_rng(1)
    n = 100
    J = np.eye(3) + rng.normal(scale=1e-3, size=(n, 3, 3))
    J[37] = [[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 0.0, 1.0]]
    f = rng.normal(size=(n, 3))
    p = rng.normal(size=(n, 3))
    with pytest.raises(Exception, match="point #37") as info:
        parametric_solvers._solve(J, f, "Newton inverse", np.arange(n), p)
    assert info.value.point_index == 37


def test_scratch_arrays_never_reach_the_caller(s500):
    """The evaluation reuses its temporaries: answers must not change by later calls, and
    slopes asked for earlier located points must not read rows reused since."""
    ref = ReferenceParametric(s500)
    rng = np.random.default_rng(9)
    assert 24 * 3 * 8000 > parametric_errors.SCRATCH_MAX_DOUBLES  # 8000 points: fresh arrays
    for n in (1, 3, 200, 8000):
        q1, q2 = points(s500, n, rng), points(s500, n, rng)
        r = tool_vectors(n, rng)
        answers = [s500.forward(q1, r), s500.jacobian(q1, r), *s500.errors_at(q1), *s500.error_derivatives(q1)]
        kept = [a.copy() for a in answers]
        s500.forward(q2, r)
        s500.jacobian(q2, r)
        s500.error_derivatives(q2)
        s500.inverse(points(s500, n, rng, outside=False), r)
        for a, b in zip(answers, kept, strict=True):
            assert same_bits(a, b)
        st = s500._stacked
        loc1 = st.locate(q1)
        st.values(loc1)
        st.values(st.locate(q2))  # reuses the rows loc1 took
        d = st.slopes(loc1)
        assert same_bits(np.ascontiguousarray(d[:3].transpose(2, 0, 1)) + s500._S, ref.error_derivatives(q1)[0])
