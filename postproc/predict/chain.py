"""A serial machine as a chain of modules from the workpiece to the tool.

Each module is a product of elements, in the order written. Seed 002 writes a module
as ``M_i(t) = M_Di(t) M_Vi(t) M_Ci`` (error, motion, constant geometry); seed 004 as
``M = M_O M_Gamma M_Phi M_Delta`` (nominal layout, position inside a tolerance field,
shaping motion, elastic displacement in the joint). Both are element lists:

==========  ===================================================================
``fixed``   constant 4x4: ``translation``, ``rotation`` (axis, angle rad),
            ``matrix``, or ``small_angle`` [u, v, w, a, b, g] (``inverse``: true
            for its matrix inverse)
``linear``  translation by a variable along ``axis`` or a ``direction`` vector
``rotary``  rotation by a variable about ``axis`` (``unit`` deg or rad)
``spindle`` rotation about ``axis`` by ``2 pi rpm/60 t + phase``, ``direction``
            ``cw`` (M03 seen from the spindle, seed 002's example) or ``ccw``
``error``   the six parameters u, v, w, alpha, beta, gamma (values, see
            :mod:`postproc.predict.values`), ``order`` ``small`` (seed 002's M_D)
            or ``exact`` (finite rotation)
``points``  frame on a triangle i, j, k whose coordinates are values (seed 004,
            formulas 10-17; tables 2 and 3)
``plane``   least-squares plane through ``nodes`` [[x, y], ...] at heights ``z``
            (values), and the frame on it above the first three nodes (formulas
            18-22; table 1)
==========  ===================================================================

A module matrix maps the next module's coordinates into this one's; the chain gives
the tool's points in the workpiece frame, ``r_s = M_1 ... M_m r_e`` (seed 002,
formula 3; seed 004, formula 24). Everything is evaluated against an environment of
variables (scalars or arrays that broadcast), so one call gives a whole trace or a
whole Monte-Carlo sample.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from postproc.errors import PostprocError
from postproc.predict import frames
from postproc.predict.values import check_value, evaluate, names_in

ERROR_PARAMS = ("u", "v", "w", "alpha", "beta", "gamma")
KINDS = ("fixed", "linear", "rotary", "spindle", "error", "points", "plane")


def _fail(where: str, message: str, hint: str | None = None) -> PostprocError:
    return PostprocError(f"{where}: {message}", hint=hint)


def _vector(body: Mapping, key: str, where: str, n: int = 3) -> np.ndarray:
    try:
        arr = np.asarray(body[key], dtype=float)
    except (KeyError, TypeError, ValueError):
        raise _fail(where, f'"{key}" must be a list of {n} numbers') from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise _fail(where, f'"{key}" must be a list of {n} finite numbers, got {body[key]!r}')
    return arr


@dataclass
class Element:
    """One factor of a module matrix; ``body`` is its JSON description."""

    kind: str
    body: dict
    where: str = "element"

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise _fail(self.where, f"unknown element kind {self.kind!r}", hint=f"use one of {', '.join(KINDS)}")
        if not isinstance(self.body, Mapping):
            raise _fail(self.where, f"{self.kind} element needs an object, got {self.body!r}")
        try:
            getattr(self, f"_check_{self.kind}")()
        except PostprocError as exc:
            raise self._placed(exc) from None

    def _placed(self, exc: PostprocError) -> PostprocError:
        """Prefix an error raised by a helper with this element's place."""
        if not exc.message.startswith(self.where):
            exc.message = f"{self.where}: {exc.message}"
            exc.args = (exc.message,)
        return exc

    # -- validation ------------------------------------------------------------------
    def _check_fixed(self) -> None:
        b, w = self.body, self.where
        keys = [k for k in ("translation", "rotation", "matrix", "small_angle") if k in b]
        if len(keys) != 1:
            raise _fail(w, "fixed element needs exactly one of translation, rotation, matrix, small_angle")
        self._const = self._fixed_matrix(keys[0])

    def _fixed_matrix(self, key: str) -> np.ndarray:
        b, w = self.body, self.where
        if key == "translation":
            return frames.translation(*_vector(b, "translation", w))
        if key == "rotation":
            rot = b["rotation"]
            if not isinstance(rot, Mapping) or not isinstance(rot.get("angle"), int | float):
                raise _fail(w, 'rotation must be {"axis": "x|y|z", "angle": radians}')
            return frames.rotation(rot.get("axis", "z"), float(rot["angle"]))
        if key == "matrix":
            m = np.asarray(b["matrix"], dtype=float)
            if m.shape != (4, 4) or not np.all(np.isfinite(m)) or not np.allclose(m[3], [0, 0, 0, 1]):
                raise _fail(w, "matrix must be 4x4 with last row 0 0 0 1")
            return m
        m = frames.small_angle_matrix(*_vector(b, "small_angle", w, 6))
        return np.linalg.inv(m) if b.get("inverse") else m

    def _check_linear(self) -> None:
        b = self.body
        if "direction" in b:
            self._dir = _vector(b, "direction", self.where)
        else:
            self._dir = np.eye(3)[frames.axis_index(b.get("axis", "x"))]
        check_value(b.get("var"), f"{self.where}.var")

    def _check_rotary(self) -> None:
        b = self.body
        frames.axis_index(b.get("axis", "z"))
        check_value(b.get("var"), f"{self.where}.var")
        if b.get("unit", "deg") not in ("deg", "rad"):
            raise _fail(self.where, 'rotary "unit" must be "deg" or "rad"')

    def _check_spindle(self) -> None:
        b = self.body
        frames.axis_index(b.get("axis", "z"))
        check_value(b.get("rpm"), f"{self.where}.rpm")
        check_value(b.get("var", "t"), f"{self.where}.var")
        check_value(b.get("phase", 0.0), f"{self.where}.phase")
        if b.get("direction", "cw") not in ("cw", "ccw"):
            raise _fail(self.where, 'spindle "direction" must be "cw" or "ccw"')

    def _check_error(self) -> None:
        b = self.body
        unknown = set(b) - set(ERROR_PARAMS) - {"order", "comment"}
        if unknown:
            raise _fail(self.where, f"unknown error parameters {sorted(unknown)}", hint=f"use {', '.join(ERROR_PARAMS)}")
        for key in ERROR_PARAMS:
            check_value(b.get(key, 0.0), f"{self.where}.{key}")
        if b.get("order", "small") not in ("small", "exact"):
            raise _fail(self.where, 'error "order" must be "small" or "exact"')

    def _check_points(self) -> None:
        for key in ("i", "j", "k"):
            pt = self.body.get(key)
            if not isinstance(pt, list) or len(pt) != 3:
                raise _fail(self.where, f'points "{key}" must be a list of 3 values')
            for n, v in enumerate(pt):
                check_value(v, f"{self.where}.{key}[{n}]")

    def _check_plane(self) -> None:
        b = self.body
        nodes = np.asarray(b.get("nodes", []), dtype=float)
        z = b.get("z")
        if nodes.ndim != 2 or nodes.shape[1] != 2 or len(nodes) < 3:
            raise _fail(self.where, 'plane "nodes" must be a list of at least 3 [x, y] pairs')
        if not isinstance(z, list) or len(z) != len(nodes):
            raise _fail(self.where, f'plane "z" must be a list of {len(nodes)} values, one per node')
        for n, v in enumerate(z):
            check_value(v, f"{self.where}.z[{n}]")
        frame = np.asarray(b.get("frame", nodes[:3].tolist()), dtype=float)
        if frame.shape != (3, 2):
            raise _fail(self.where, 'plane "frame" must be three [x, y] nodes')
        self._nodes, self._frame = nodes, frame

    # -- evaluation ------------------------------------------------------------------
    def matrix(self, env: Mapping[str, Any]) -> np.ndarray:
        """The element's transform(s), shape ``S + (4, 4)`` with ``S`` from the variables."""
        try:
            return self._matrix(env)
        except PostprocError as exc:
            raise self._placed(exc) from None

    def _matrix(self, env: Mapping[str, Any]) -> np.ndarray:
        b, w = self.body, self.where
        if self.kind == "fixed":
            return self._const
        if self.kind == "linear":
            s = evaluate(b["var"], env, f"{w}.var") * float(b.get("scale", 1.0))
            return frames.translation_along(self._dir, s)
        if self.kind == "rotary":
            a = evaluate(b["var"], env, f"{w}.var") * float(b.get("scale", 1.0))
            return frames.rotation(b.get("axis", "z"), np.radians(a) if b.get("unit", "deg") == "deg" else a)
        if self.kind == "spindle":
            t = evaluate(b.get("var", "t"), env, f"{w}.var")
            rpm = evaluate(b["rpm"], env, f"{w}.rpm")
            sign = -1.0 if b.get("direction", "cw") == "cw" else 1.0
            angle = sign * 2.0 * np.pi * rpm / 60.0 * t + evaluate(b.get("phase", 0.0), env, f"{w}.phase")
            return frames.rotation(b.get("axis", "z"), angle)
        if self.kind == "error":
            vals = [evaluate(b.get(k, 0.0), env, f"{w}.{k}") for k in ERROR_PARAMS]
            make = frames.exact_error_matrix if b.get("order", "small") == "exact" else frames.small_angle_matrix
            return make(*vals)
        if self.kind == "points":
            pts = []
            for key in ("i", "j", "k"):
                comps = np.broadcast_arrays(*(evaluate(v, env, f"{w}.{key}") for v in b[key]))
                pts.append(np.stack(comps, axis=-1))
            return frames.pose_from_points(*pts)
        # plane
        z = np.broadcast_arrays(*(evaluate(v, env, f"{w}.z[{n}]") for n, v in enumerate(b["z"])))
        coef = frames.fit_plane(self._nodes, np.stack(z, axis=-1))
        return frames.pose_on_plane(coef, self._frame)

    def variables(self) -> set[str]:
        b = self.body
        if self.kind == "fixed":
            return set()
        if self.kind in ("linear", "rotary"):
            return names_in(b["var"])
        if self.kind == "spindle":
            return names_in(b.get("var", "t")) | names_in(b["rpm"]) | names_in(b.get("phase", 0.0))
        if self.kind == "error":
            return set().union(*(names_in(b.get(k, 0.0)) for k in ERROR_PARAMS))
        if self.kind == "points":
            return set().union(*(names_in(v) for key in ("i", "j", "k") for v in b[key]))
        return set().union(*(names_in(v) for v in b["z"]))

    def to_dict(self) -> dict:
        return {self.kind: self.body}


@dataclass
class Module:
    """A named product of elements (one block of the machine)."""

    name: str
    elements: list[Element] = field(default_factory=list)

    def matrix(self, env: Mapping[str, Any]) -> np.ndarray:
        m = np.eye(4)
        for el in self.elements:
            m = m @ el.matrix(env)
        return m

    def to_dict(self) -> dict:
        return {"name": self.name, "elements": [e.to_dict() for e in self.elements]}


@dataclass
class Chain:
    """Modules from the workpiece (first) to the tool (last), plus random variables."""

    modules: list[Module]
    name: str = "chain"
    random: dict = field(default_factory=dict)
    description: str = ""
    defaults: dict = field(default_factory=dict)  # variable values used when not given

    def matrix(self, env: Mapping[str, Any] | None = None) -> np.ndarray:
        """``M = M_1 ... M_m``: tool-frame -> workpiece-frame transforms, shape ``S + (4, 4)``."""
        env = {**self.defaults, **(env or {})}
        m = np.eye(4)
        for mod in self.modules:
            m = m @ mod.matrix(env)
        return m

    def transform(self, points, env: Mapping[str, Any] | None = None) -> np.ndarray:
        """Tool-frame points (..., 3) in the workpiece frame; shapes broadcast with ``S``."""
        m = self.matrix(env)
        pts = np.asarray(points, dtype=float)
        return frames.apply(m, pts)

    def variables(self) -> set[str]:
        """Every variable name the chain refers to."""
        return set().union(*(e.variables() for m in self.modules for e in m.elements)) if self.modules else set()

    def to_dict(self) -> dict:
        out = {"format": CHAIN_FORMAT, "version": 1, "name": self.name}
        if self.description:
            out["description"] = self.description
        if self.defaults:
            out["defaults"] = self.defaults
        if self.random:
            out["random"] = self.random
        out["modules"] = [m.to_dict() for m in self.modules]
        return out


CHAIN_FORMAT = "postproc chain"


def element_from_dict(data: Any, where: str) -> Element:
    if not isinstance(data, Mapping):
        raise _fail(where, f"an element must be an object like {{\"linear\": {{...}}}}, got {data!r}")
    keys = [k for k in data if k != "comment"]
    if len(keys) != 1:
        raise _fail(where, f"an element has exactly one kind key, got {sorted(keys)}", hint=f"one of {', '.join(KINDS)}")
    return Element(keys[0], data[keys[0]], where)


def chain_from_dict(data: Any, where: str = "chain") -> Chain:
    """Build a :class:`Chain` from its JSON description (see ``docs/predict.md``)."""
    if not isinstance(data, Mapping) or data.get("format") != CHAIN_FORMAT:
        raise _fail(where, f'not a chain description: "format" must be "{CHAIN_FORMAT}"')
    mods = data.get("modules")
    if not isinstance(mods, list) or not mods:
        raise _fail(where, '"modules" must be a non-empty list')
    modules = []
    for i, mod in enumerate(mods):
        w = f"{where}: modules[{i}]"
        if not isinstance(mod, Mapping) or not isinstance(mod.get("elements"), list):
            raise _fail(w, 'a module needs "name" and a list "elements"')
        name = str(mod.get("name", f"module{i + 1}"))
        els = [element_from_dict(e, f"{w} ({name}).elements[{j}]") for j, e in enumerate(mod["elements"])]
        modules.append(Module(name, els))
    random = data.get("random", {})
    if not isinstance(random, Mapping):
        raise _fail(where, '"random" must be an object name -> distribution')
    from postproc.predict.tolerance import check_distribution

    for name, dist in random.items():
        check_distribution(dist, f"{where}: random.{name}")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, Mapping) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) for v in defaults.values()
    ):
        raise _fail(where, '"defaults" must map variable names to numbers')
    return Chain(modules, str(data.get("name", "chain")), dict(random), str(data.get("description", "")),
                 {str(k): float(v) for k, v in defaults.items()})
