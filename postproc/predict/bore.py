"""The bored-hole example of seed 004: position error of a hole centre.

One section of the hole is sampled as in the seed's table 4: eight positions of the
tool tip around the circle (every 45 degrees of spindle rotation, in the seed's order)
and one point on the tool axis, all at the tool overhang along the spindle axis. The
chain carries them into the workpiece frame; the centre of the machined section is the
least-squares circle through the eight points, in the plane normal to the spindle axis.
Its error against the nominal centre is checked against the +- tolerances (a square
zone, the hatched square of the seed's figure 12).

The seed's table 4 puts the eight points at radius 35 mm (24.749 = 35 / sqrt 2),
although the hole is 50 mm; here the radius is half the given diameter.

The tool turns with the spindle angle ``S`` (deg): an element that depends on ``S``
(e.g. ``{"rotary": {"axis": "x", "var": "S"}}``) or a ``spindle`` element, which in a
bore section is turned by ``S`` instead of its ``rpm`` and time. A chain in which
nothing turns the tool about the bore axis gives no circle, and is refused by name.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from postproc.errors import PostprocError
from postproc.predict import tolerance
from postproc.predict.chain import Chain
from postproc.predict.frames import axis_index
from postproc.predict.operation import Operation

#: Spindle angles of the seed's table 4 points 1-8 (deg), then the axis point 9.
TABLE4_ANGLES_DEG = np.array([0.0, 90.0, 180.0, 270.0, 45.0, 135.0, 225.0, 315.0, 0.0])

#: The eight section points must spread over a circle. Their larger principal spread
#: (singular value of the centred points, 2 r for eight points on a circle of radius r)
#: below this fraction of the diameter means they coincide: nothing turns the tool
#: (rounding leaves some 1e-15 of it).
SECTION_COINCIDENT_RATIO = 1e-9

#: The smaller spread below this fraction of the larger means the points lie on a line:
#: no circle passes through them (the least-squares circle is singular).
SECTION_LINE_RATIO = 1e-9

#: A section is a hole the tool bored when its points lie on a circle of about the
#: tool's size: the spread of their distances from the centre (roundness) and the
#: difference of its diameter from the tool's both below this fraction of the tool's
#: radius. A tool turning about an axis tilted by theta from the bore axis leaves an
#: ellipse of roundness r (1 - cos theta): at 60 degrees half the radius. Machine
#: errors and the seed's turning loads leave micrometres on tens of millimetres.
SECTION_ROUND_RATIO = 0.5


def section_axes(axis: str) -> tuple[int, int]:
    """The two workpiece axes spanning the section plane normal to the spindle ``axis``."""
    i = axis_index(axis)
    return (i + 1) % 3, (i + 2) % 3


def tool_points(op: Operation) -> np.ndarray:
    """Table 4 in the spindle frame: (9, 3), tip at the overhang, radius d/2 (point 9 on axis)."""
    i = axis_index(op.params["axis"])
    a, b = section_axes(op.params["axis"])
    pts = np.zeros((9, 3))
    pts[:, i] = op.params["overhang_mm"]
    pts[:8, a] = op.params["diameter_mm"] / 2.0
    return pts


def bore_chain(op: Operation) -> Chain:
    """The operation's chain with its spindle elements turned by the section angle."""
    chain = op.chain
    return chain.spindle_turned_by(op.params["spindle_var"]) if chain.has_spindle() else chain


def section_points(op: Operation, env: Mapping[str, float | np.ndarray] | None = None) -> np.ndarray:
    """Workpiece-frame points (n, 9, 3) of the section for variables ``env`` (arrays (n,)).

    With no variables in ``env`` (or none the chain depends on) the result is one
    section per draw, (1, 9, 3) for an empty ``env``.
    """
    arrays = {k: np.asarray(v, dtype=float) for k, v in (env or {}).items()}
    n = max((v.size for v in arrays.values()), default=1)
    full = {**op.context, **{k: v.reshape(-1)[:, None] for k, v in arrays.items()}}
    full[op.params["spindle_var"]] = TABLE4_ANGLES_DEG
    pts = bore_chain(op).transform(tool_points(op), full)
    # whatever the chain depends on, one section per draw
    return np.broadcast_to(pts, (n, 9, 3))


def _refuse(op: Operation, message: str) -> PostprocError:
    axis, var = op.params["axis"], op.params["spindle_var"]
    hint = (f'turn the tool about the bore axis {axis}: a {{"spindle": {{"axis": "{axis}", "rpm": 0}}}} element, '
            f'or {{"rotary": {{"axis": "{axis}", "var": "{var}"}}}}, after the modules that carry it')
    return PostprocError(message, path=op.path, hint=hint)


def check_section(op: Operation, plane_points: np.ndarray) -> None:
    """Refuse sections (..., 8, 2) whose points coincide or lie on a line: no circle fits."""
    x = plane_points - plane_points.mean(axis=-2, keepdims=True)
    spread = np.linalg.svd(x, compute_uv=False).reshape(-1, 2)
    var = op.params["spindle_var"]
    if np.any(spread[:, 0] <= SECTION_COINCIDENT_RATIO * op.params["diameter_mm"]):
        raise _refuse(op, f"the eight section points coincide: nothing in the chain turns the tool with the "
                          f"spindle angle '{var}'")
    if np.any(spread[:, 1] <= SECTION_LINE_RATIO * spread[:, 0]):
        raise _refuse(op, f"the eight section points lie on a line in the {'-'.join(component_names(op))} plane: "
                          f"the tool turns with '{var}' about an axis normal to the bore axis {op.params['axis']}")


def check_round(op: Operation, diameter_mm: np.ndarray, roundness_mm: np.ndarray) -> None:
    """Refuse sections that are no circle of about the tool's diameter (see SECTION_ROUND_RATIO)."""
    d = op.params["diameter_mm"]
    off = np.maximum(roundness_mm, np.abs(diameter_mm - d))
    bad = off > SECTION_ROUND_RATIO * d / 2.0
    if np.any(bad):
        k = int(np.argmax(off))
        raise _refuse(op, f"the eight section points lie on no circle of the tool's diameter {d:g} mm (their "
                          f"circle {float(np.ravel(diameter_mm)[k]):.4g} mm, out of round by "
                          f"{float(np.ravel(roundness_mm)[k]):.4g} mm): the tool turns with "
                          f"'{op.params['spindle_var']}' about an axis more than 60 degrees off the bore axis "
                          f"{op.params['axis']}, or a variable moves it along the section")


def circle_centre(points) -> np.ndarray:
    """Least-squares (algebraic) circle centre of 2D points (..., k, 2) -> (..., 2)."""
    pts = np.asarray(points, dtype=float)
    mean = pts.mean(axis=-2, keepdims=True)
    x = pts - mean
    a = np.concatenate([2 * x, np.ones(x.shape[:-1] + (1,))], axis=-1)
    rhs = np.sum(x * x, axis=-1)
    ata = np.swapaxes(a, -1, -2) @ a
    atb = np.einsum("...ki,...k->...i", a, rhs)
    sol = np.linalg.solve(ata, atb[..., None])[..., 0]
    return sol[..., :2] + mean[..., 0, :]


@dataclass
class Section:
    """One evaluated section: workpiece points (9, 3), fitted centre and its error (2,)."""

    points_mm: np.ndarray
    centre_mm: np.ndarray
    axis_point_mm: np.ndarray
    error_mm: np.ndarray
    names: list[str]
    diameter_mm: float = float("nan")  # of the least-squares circle
    roundness_mm: float = float("nan")  # max - min distance of the eight points from its centre


def fit_sections(op: Operation, env: Mapping[str, float | np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre error (n, 2), diameter (n,) and roundness (n,) of the sections for n sets of variables."""
    a, b = section_axes(op.params["axis"])
    plane = section_points(op, env)[..., :8, [a, b]]
    check_section(op, plane)
    centre = circle_centre(plane)
    radii = np.linalg.norm(plane - centre[..., None, :], axis=-1)
    diameter, roundness = 2.0 * radii.mean(axis=-1), radii.max(axis=-1) - radii.min(axis=-1)
    check_round(op, diameter, roundness)
    return centre - op.params["nominal_centre_mm"], diameter, roundness


def centre_errors(op: Operation, env: Mapping[str, np.ndarray]) -> np.ndarray:
    """Centre error (n, 2) in the section plane for n sets of variables."""
    return fit_sections(op, env)[0]


def component_names(op: Operation) -> list[str]:
    a, b = section_axes(op.params["axis"])
    return ["XYZ"[a], "XYZ"[b]]


def evaluate_section(op: Operation, values: Mapping[str, float]) -> Section:
    """The section for one set of random-variable values (e.g. the worst corner)."""
    a, b = section_axes(op.params["axis"])
    env = {k: np.asarray([v]) for k, v in values.items()}
    pts = section_points(op, env)[0]
    check_section(op, pts[:8, [a, b]])
    centre = circle_centre(pts[:8, [a, b]])
    radii = np.linalg.norm(pts[:8, [a, b]] - centre, axis=1)
    check_round(op, 2 * radii.mean(), radii.max() - radii.min())
    return Section(pts, centre, pts[8], centre - op.params["nominal_centre_mm"], component_names(op),
                   float(2 * radii.mean()), float(radii.max() - radii.min()))


def is_deterministic(op: Operation) -> bool:
    """True when no random variable the chain uses can vary: one prediction, no Monte Carlo."""
    return not tolerance.varying(op.chain.random, op.chain.variables())


def diameter_range(op: Operation) -> tuple[float, float]:
    """Smallest and largest section diameter over the corners of the variables' box
    (the single prediction for a deterministic chain)."""
    env = tolerance.nominal(op.chain.random) if is_deterministic(op) else tolerance.corners(op.chain.random)
    d = fit_sections(op, env)[1]
    return float(d.min()), float(d.max())


def verdict(op: Operation, worst: tolerance.WorstCase, diameters: tuple[float, float]) -> dict:
    """Whether the tolerance (and the diameter limits) are held: in the worst case over the
    corners of the fields, or by the single prediction of a deterministic chain."""
    limits = op.params.get("diameter_limits_mm")
    dia = None if limits is None else bool(limits[0] <= diameters[0] and diameters[1] <= limits[1])
    return {
        "held": bool(worst.within and dia is not False),
        "basis": "single prediction" if is_deterministic(op) else "worst case",
        "centre_within": worst.within,
        "diameter_within": dia,
        "diameter_range_mm": list(diameters),
    }


def analyse(op: Operation, n: int | None = None, seed: int | None = None):
    """Monte Carlo and worst case of the centre error -> (Distribution, WorstCase).

    A deterministic chain (no random variable that varies) gives the single
    prediction as its worst case and no distribution: ``(None, WorstCase)``.
    """
    random = op.chain.random
    names = component_names(op)
    tol = op.params["tolerance_mm"]

    def fn(env):
        return centre_errors(op, env)

    if is_deterministic(op):
        return None, tolerance.single(fn, tolerance.nominal(random), tolerance_mm=tol, names=names)
    dist = tolerance.monte_carlo(
        fn, random, n=n or op.params["n"], seed=op.params["seed"] if seed is None else seed,
        tolerance_mm=tol, names=names,
    )
    worst = tolerance.worst_case(fn, random, tolerance_mm=tol, names=names)
    return dist, worst


def _nominal_angles(offsets: np.ndarray) -> np.ndarray:
    """Angles (rad) of the eight tips on an error-free machine: ``sense * S + phase``, the
    sense (the spindle may turn either way) and phase that best fit where they are."""
    s = np.radians(TABLE4_ANGLES_DEG[:8])
    seen = np.arctan2(offsets[:, 1], offsets[:, 0])
    fits = []
    for sense in (1.0, -1.0):
        phase = np.angle(np.mean(np.exp(1j * (seen - sense * s))))
        miss = float(np.sum(1.0 - np.cos(seen - sense * s - phase)))
        fits.append((miss, sense * s + phase))
    return min(fits, key=lambda f: f[0])[1]  # the first of equals, as before


def plot_bore(op: Operation, nominal: Section, worst: Section, dist, magnify: float = 100.0, ax=None):
    """Seed 004 figure 12: nominal circle, machined section (errors magnified), tolerance
    square and the Monte-Carlo centres -> axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(1, 2, figsize=(12, 5.6))
    a, b = section_axes(op.params["axis"])
    c0 = op.params["nominal_centre_mm"]
    r = op.params["diameter_mm"] / 2.0
    th = np.linspace(0, 2 * np.pi, 361)
    left = ax[0]
    left.plot(c0[0] + r * np.cos(th), c0[1] + r * np.sin(th), "k-", lw=1, label="nominal hole")
    left.plot(*c0, "k+", ms=12)
    order = [0, 4, 1, 5, 2, 6, 3, 7, 0]
    for sec, style, label in ((nominal, "b.-", "all variables mid-field"), (worst, "r.-", "worst corner")):
        act = sec.points_mm[:8][:, [a, b]]
        phi = _nominal_angles(act - sec.centre_mm)
        nom = np.stack([c0[0] + r * np.cos(phi), c0[1] + r * np.sin(phi)], axis=1)
        shown = nom + magnify * (act - nom)
        left.plot(shown[order, 0], shown[order, 1], style, lw=1, label=f"{label} (errors x{magnify:g})")
        left.quiver(nom[:, 0], nom[:, 1], shown[:, 0] - nom[:, 0], shown[:, 1] - nom[:, 1],
                    angles="xy", scale_units="xy", scale=1, color=style[0], width=0.004, alpha=0.6)
        centre = c0 + magnify * sec.error_mm
        left.plot(*centre, style[0] + "+", ms=12)
    left.set_aspect("equal")
    left.set_xlabel(f"{'XYZ'[a]} (mm)")
    left.set_ylabel(f"{'XYZ'[b]} (mm)")
    left.set_title("section of the bored hole")
    left.legend(fontsize=8, loc="lower right")
    right = ax[1]
    tol = op.params["tolerance_mm"]
    names = component_names(op)
    right.add_patch(plt.Rectangle((-tol[0] * 1e3, -tol[1] * 1e3), 2 * tol[0] * 1e3, 2 * tol[1] * 1e3,
                                  fill=False, hatch="//", ec="grey", label="tolerance zone"))
    if dist is None:  # a deterministic chain: its one centre
        right.plot(*(nominal.error_mm * 1e3), "kx", ms=9, label="predicted centre")
        right.set_title("centre error (no random variables)")
    else:
        s = dist.samples_mm * 1e3
        inside = dist.within
        right.plot(s[inside, 0], s[inside, 1], ".", ms=1.5, color="tab:green", label="Monte-Carlo centre, in")
        right.plot(s[~inside, 0], s[~inside, 1], ".", ms=1.5, color="tab:red", label="Monte-Carlo centre, out")
        right.plot(*(worst.error_mm * 1e3), "kx", ms=9, label="worst corner")
        right.set_title(f"centre error: P(within) = {dist.p_within:.4f}, n = {len(s)}")
    right.set_aspect("equal")
    right.set_xlabel(f"centre error {names[0]} (µm)")
    right.set_ylabel(f"centre error {names[1]} (µm)")
    right.legend(fontsize=8, loc="lower left")
    ax[0].figure.tight_layout()
    return ax
