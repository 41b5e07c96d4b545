"""The 21-parameter model written as a serial chain (formats.md sign conventions).

Modules, from the workpiece to the tool::

    X axis:  linear X,           error (u, v, w) = (EX, EY, EZ)_X(X)
    Y axis:  squareness S_Y, linear Y, S_Y^-1,   error (EX, EY, EZ)_Y(Y)
    Z axis:  squareness S_Z, linear Z, S_Z^-1,   error (EX, EY, EZ)_Z(Z)
    angles:  error (alpha, beta, gamma) = sum over axes of (EA, EB, EC)_i(q_i)

``S_Y`` is the constant small-angle matrix with ``gamma = EC0Y`` (the Y motion then
runs along ``(-EC0Y, 1, 0)``), ``S_Z`` the one with ``alpha = EA0Z, beta = EB0Z``
(Z runs along ``(EB0Z, -EA0Z, 1)``). The chain's tool point is then exactly
``q + rho(q) + R r`` with ``R`` the small-angle matrix (order "small": the first-order
formula) or the finite rotation ``exp([eps]x)`` (order "exact").

``angular="per-axis"`` gives each axis its own angular error matrix instead
(``R_X R_Y R_Z``), as a physical chain would: that differs from the summed rotation
by the products of angles of different axes (second order).

Table values are interpolated linearly between rows, as controllers do.
"""

from __future__ import annotations

import numpy as np

from postproc.predict.chain import Chain, Element, Module

AXES = ("X", "Y", "Z")
_LINEAR = ("u", "v", "w")
_ANGULAR = ("alpha", "beta", "gamma")


def _table(var: str, positions, values) -> dict:
    return {"var": var, "table": {"positions": [float(x) for x in positions], "values": [float(v) for v in values]}}


def chain_from_tables(tables, squareness=None, *, order: str = "exact", angular: str = "summed") -> Chain:
    """Chain for axis error tables (``position_mm[axis]``, ``errors[axis]`` (n, 6))."""
    if angular not in ("summed", "per-axis"):
        raise ValueError(f"angular must be 'summed' or 'per-axis', got {angular!r}")
    sq = {"EC0Y": 0.0, "EB0Z": 0.0, "EA0Z": 0.0}
    if squareness is not None:
        sq.update({k: float(getattr(squareness, k)) for k in sq})
    modules = []
    for ax in AXES:
        pos = np.asarray(tables.position_mm[ax], dtype=float)
        err = np.asarray(tables.errors[ax], dtype=float)
        elements = []
        if ax == "Y":
            s = [0, 0, 0, 0, 0, sq["EC0Y"]]
        elif ax == "Z":
            s = [0, 0, 0, sq["EA0Z"], sq["EB0Z"], 0]
        else:
            s = None
        if s is not None:
            elements.append(Element("fixed", {"small_angle": s}, f"{ax} squareness"))
        elements.append(Element("linear", {"axis": ax.lower(), "var": ax}, f"{ax} motion"))
        if s is not None:
            elements.append(Element("fixed", {"small_angle": s, "inverse": True}, f"{ax} squareness back"))
        body = {name: _table(ax, pos, err[:, j]) for j, name in enumerate(_LINEAR)}
        elements.append(Element("error", {**body, "order": "small"}, f"{ax} linear errors"))
        modules.append(Module(f"{ax} axis", elements))
    if angular == "summed":
        body = {
            name: {"sum": [_table(ax, tables.position_mm[ax], np.asarray(tables.errors[ax])[:, 3 + j]) for ax in AXES]}
            for j, name in enumerate(_ANGULAR)
        }
        modules.append(Module("angular errors", [Element("error", {**body, "order": order}, "angular errors")]))
    else:
        for ax in AXES:
            err = np.asarray(tables.errors[ax], dtype=float)
            body = {name: _table(ax, tables.position_mm[ax], err[:, 3 + j]) for j, name in enumerate(_ANGULAR)}
            modules.append(Module(f"{ax} angular errors", [Element("error", {**body, "order": order}, f"{ax} angles")]))
    return Chain(modules, "21-parameter model", description="axis error tables and squareness as a serial chain")


def tool_points(chain: Chain, q, r) -> np.ndarray:
    """Tool points (N, 3) of the chain at commanded positions ``q`` (N, 3), tool vectors ``r``."""
    q = np.asarray(q, dtype=float)
    env = {"X": q[:, 0], "Y": q[:, 1], "Z": q[:, 2]}
    return chain.transform(np.broadcast_to(np.asarray(r, dtype=float), q.shape), env)
