"""The linear part of a Sinumerik programmable frame (rotation, scale, mirror) and the
maps between a program's coordinates and the machine's under it.

SINUMERIK 840D sl Programming Manual Fundamentals, "Coordinate transformations (frames)":
a position programmed in the frame is, in work coordinates, ``T + A p``: ``A`` is built by
``ROT``/``SCALE``/``MIRROR`` (each replacing the programmable frame) and ``AROT``/``ASCALE``/
``AMIRROR`` (each acting in the coordinates the frame has made so far, ``A := A B``), and
``ATRANS v`` adds ``A v`` to ``T``. In machine coordinates, with ``s`` the work offset plus
``T`` plus the tool length along Z, a point that reads ``P = s + p`` without the linear part
is at ``s + A (P - s)``: :func:`machine_from_program` and its inverse.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

Frame = tuple[float, ...]  # 3x3 row-major
IDENTITY: Frame = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
# a scale factor's or an angle's rounding: a frame within this of the identity is none
FRAME_EPS = 1e-12


def product(a: Frame, b: Frame) -> Frame:
    """``a b`` (``b`` applied first)."""
    return tuple(sum(a[3 * i + k] * b[3 * k + j] for k in range(3)) for i in range(3) for j in range(3))


def rotation_z(angle_deg: float) -> Frame:
    """A rotation by ``angle_deg`` about Z, counter-clockwise seen from +Z (ROT Z=, RPL= in G17)."""
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return (c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)


def diagonal(x: float, y: float, z: float) -> Frame:
    return (x, 0.0, 0.0, 0.0, y, 0.0, 0.0, 0.0, z)


def inverse(a: Frame) -> Frame:
    m = a
    det = determinant(a)
    cof = (m[4] * m[8] - m[5] * m[7], m[2] * m[7] - m[1] * m[8], m[1] * m[5] - m[2] * m[4],
           m[5] * m[6] - m[3] * m[8], m[0] * m[8] - m[2] * m[6], m[2] * m[3] - m[0] * m[5],
           m[3] * m[7] - m[4] * m[6], m[1] * m[6] - m[0] * m[7], m[0] * m[4] - m[1] * m[3])
    return tuple(v / det for v in cof)


def determinant(a: Frame) -> float:
    return (a[0] * (a[4] * a[8] - a[5] * a[7]) - a[1] * (a[3] * a[8] - a[5] * a[6])
            + a[2] * (a[3] * a[7] - a[4] * a[6]))


def apply(a: Frame, v: Sequence[float]) -> tuple[float, float, float]:
    """``a v``; a zero entry ignores its component, so an unknown (NaN) axis the frame does
    not mix into another stays unknown there only."""
    return tuple(sum(a[3 * i + j] * v[j] for j in range(3) if a[3 * i + j] != 0.0) for i in range(3))  # type: ignore[return-value]


def is_identity(a: Frame) -> bool:
    return all(abs(x - y) <= FRAME_EPS for x, y in zip(a, IDENTITY, strict=True))


def machine_from_program(a: Frame, shift: Sequence[float], p: Sequence[float]) -> tuple[float, float, float]:
    """The machine point of ``p`` (a point computed as if the frame had no linear part)."""
    d = apply(a, [p[k] - shift[k] for k in range(3)])
    return (shift[0] + d[0], shift[1] + d[1], shift[2] + d[2])


def program_from_machine(a: Frame, shift: Sequence[float], q: Sequence[float]) -> tuple[float, float, float]:
    """The inverse of :func:`machine_from_program`."""
    return machine_from_program(inverse(a), shift, q)


def keeps_circles(a: Frame, axes: tuple[int, int, int] = (0, 1, 2)) -> bool:
    """Whether ``a`` maps a circle in the plane of ``axes`` (its two in-plane axes, then the
    normal: ``PLANES``) onto a circle in that plane: it keeps the plane and its normal, and
    scales both in-plane axes alike (a rotation in the plane, possibly mirrored)."""
    p, q, n = axes

    def at(i: int, j: int) -> float:
        return a[3 * i + j]

    u, v = (at(p, p), at(q, p)), (at(p, q), at(q, q))
    return (abs(u[0] * v[0] + u[1] * v[1]) <= FRAME_EPS and abs(math.hypot(*u) - math.hypot(*v)) <= FRAME_EPS
            and at(n, p) == at(n, q) == at(p, n) == at(q, n) == 0.0)


def reverses_arcs(a: Frame, axes: tuple[int, int, int] = (0, 1, 2)) -> bool:
    """Whether ``a`` turns the arcs of the plane of ``axes`` the other way (a mirror of one of
    its two axes: G2 becomes G3; a mirror of the normal alone does not)."""
    p, q, _n = axes
    return bool(a[3 * p + p] * a[3 * q + q] - a[3 * p + q] * a[3 * q + p] < 0)  # (a bool, not numpy's)


def next_frame(kind: str, frame: Frame | None, translation: Sequence[float], given: dict[str, float],
               angle_deg: float | None, unit_mm: float) -> tuple[Frame | None, list[float]]:
    """The programmable frame after the instruction ``kind`` (TRANS, ATRANS, ROT, AROT,
    SCALE, ASCALE, MIRROR, AMIRROR) with its axis values ``given`` (program units; for ROT
    the angle about Z is ``angle_deg``): its linear part (None: the identity) and its
    translation (mm, work axes). The caller has checked the words."""
    additive = kind.startswith("A")
    a = (frame or IDENTITY) if additive else IDENTITY
    t = list(translation) if additive else [0.0, 0.0, 0.0]
    base = kind[1:] if additive else kind
    values = [given.get(axis) for axis in "XYZ"]
    if base == "TRANS":
        d = apply(a, [(v or 0.0) * unit_mm for v in values])
        t = [t[k] + d[k] for k in range(3)]
    elif base == "ROT" and angle_deg is not None:
        a = product(a, rotation_z(angle_deg))
    elif base == "SCALE" and any(v is not None for v in values):
        a = product(a, diagonal(*(1.0 if v is None else v for v in values)))
    elif base == "MIRROR" and any(v is not None for v in values):
        a = product(a, diagonal(*(1.0 if v is None else -1.0 for v in values)))
    return (None if is_identity(a) else a), t
