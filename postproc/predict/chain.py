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
``calibration``  a calibration file made by ``postproc fit``: the machine's
            volumetric error at the commanded position ``at`` (values, default
            X, Y, Z), from the calibration's forward model with its effects
==========  ===================================================================

A module matrix maps the next module's coordinates into this one's; the chain gives
the tool's points in the workpiece frame, ``r_s = M_1 ... M_m r_e`` (seed 002,
formula 3; seed 004, formula 24). Everything is evaluated against an environment of
variables (scalars or arrays that broadcast), so one call gives a whole trace or a
whole Monte-Carlo sample.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from postproc.errors import PostprocError
from postproc.predict import frames
from postproc.predict.values import check_value, evaluate, names_in

ERROR_PARAMS = ("u", "v", "w", "alpha", "beta", "gamma")
KINDS = ("fixed", "linear", "rotary", "spindle", "error", "points", "plane", "calibration")

#: The fields each element kind reads ("comment" is allowed everywhere); any other key
#: is refused, so that a misspelt field is not silently ignored.
FIELDS = {
    "fixed": ("translation", "rotation", "matrix", "small_angle", "inverse"),
    "linear": ("axis", "direction", "var", "scale"),
    "rotary": ("axis", "var", "unit", "scale"),
    "spindle": ("axis", "rpm", "var", "phase", "direction"),
    "error": (*ERROR_PARAMS, "order"),
    "points": ("i", "j", "k"),
    "plane": ("nodes", "z", "frame"),
    "calibration": ("file", "at", "context"),
}

#: The calibration element differences the calibration's forward model over tool
#: vectors this long (mm) to get its rotation part; the models are affine in the tool
#: vector, so any length gives the same matrix, and a machine-sized one keeps the
#: rounding of positions of some 100 mm out of the difference.
CALIBRATION_LEVER_MM = 100.0


def _fail(where: str, message: str, hint: str | None = None) -> PostprocError:
    return PostprocError(f"{where}: {message}", hint=hint)


def _is_number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and bool(np.isfinite(x))


def _array(value: Any, shape: tuple, what: str, where: str) -> np.ndarray:
    """``value`` as a float array of ``shape`` holding finite JSON numbers, or raise."""
    def numbers(v, dims):
        if not dims:
            return _is_number(v)
        return isinstance(v, list) and len(v) == dims[0] and all(numbers(x, dims[1:]) for x in v)

    if not numbers(value, shape):
        size = f"a list of {shape[0]}" if len(shape) == 1 else f"a {' x '.join(map(str, shape))} list of"
        raise _fail(where, f"{what} must be {size} finite numbers, got {value!r}")
    return np.asarray(value, dtype=float)


def _vector(body: Mapping, key: str, where: str, n: int = 3) -> np.ndarray:
    return _array(body.get(key), (n,), f'"{key}"', where)


def _scale(body: Mapping, where: str) -> float:
    scale = body.get("scale", 1.0)
    if not _is_number(scale):
        raise _fail(where, f'"scale" must be a finite number, got {scale!r}')
    return float(scale)


@dataclass
class Element:
    """One factor of a module matrix; ``body`` is its JSON description."""

    kind: str
    body: Any
    where: str = "element"
    base_dir: Path | None = None  # calibration files are found relative to it

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise _fail(self.where, f"unknown element kind {self.kind!r}", hint=f"use one of {', '.join(KINDS)}")
        if self.kind == "calibration" and isinstance(self.body, str):
            self.body = {"file": self.body}
            self._short = True  # written back as {"calibration": "file.json"}
        if not isinstance(self.body, Mapping):
            raise _fail(self.where, f"{self.kind} element needs an object, got {self.body!r}")
        unknown = sorted(set(self.body) - set(FIELDS[self.kind]) - {"comment"})
        if unknown:
            what = "error parameters" if self.kind == "error" else f"{self.kind} field(s)"
            raise _fail(self.where, f"unknown {what} {unknown}",
                        hint=f"a {self.kind} element takes {', '.join(FIELDS[self.kind])}")
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
        if "inverse" in b and (key != "small_angle" or not isinstance(b["inverse"], bool)):
            raise _fail(w, '"inverse" is true or false, and only with "small_angle"')
        if key == "translation":
            return frames.translation(*_vector(b, "translation", w))
        if key == "rotation":
            rot = b["rotation"]
            if not isinstance(rot, Mapping) or not _is_number(rot.get("angle")) or set(rot) - {"axis", "angle"}:
                raise _fail(w, f'rotation must be {{"axis": "x|y|z", "angle": radians}}, got {rot!r}')
            return frames.rotation(rot.get("axis", "z"), float(rot["angle"]))
        if key == "matrix":
            m = _array(b["matrix"], (4, 4), "matrix", w)
            if not np.array_equal(m[3], [0, 0, 0, 1]):
                raise _fail(w, "matrix must be 4x4 with last row 0 0 0 1")
            if abs(np.linalg.det(m[:3, :3])) < frames.COLLINEAR_RATIO:
                raise _fail(w, "matrix is singular: its 3x3 part maps the next frame onto a plane or line")
            return m
        m = frames.small_angle_matrix(*_vector(b, "small_angle", w, 6))
        return np.linalg.inv(m) if b.get("inverse") else m

    def _check_linear(self) -> None:
        b = self.body
        if "direction" in b and "axis" in b:
            raise _fail(self.where, 'a linear element takes "axis" or "direction", not both')
        if "direction" in b:
            self._dir = _vector(b, "direction", self.where)
        else:
            self._dir = np.eye(3)[frames.axis_index(b.get("axis", "x"))]
        check_value(b.get("var"), f"{self.where}.var")
        self._scale = _scale(b, self.where)

    def _check_rotary(self) -> None:
        b = self.body
        frames.axis_index(b.get("axis", "z"))
        check_value(b.get("var"), f"{self.where}.var")
        if b.get("unit", "deg") not in ("deg", "rad"):
            raise _fail(self.where, 'rotary "unit" must be "deg" or "rad"')
        self._scale = _scale(b, self.where)

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
        b, w = self.body, self.where
        raw = b.get("nodes")
        if not isinstance(raw, list) or len(raw) < 3:
            raise _fail(w, 'plane "nodes" must be a list of at least 3 [x, y] pairs')
        nodes = _array(raw, (len(raw), 2), 'plane "nodes"', w)
        z = b.get("z")
        if not isinstance(z, list) or len(z) != len(nodes):
            raise _fail(w, f'plane "z" must be a list of {len(nodes)} values, one per node')
        for n, v in enumerate(z):
            check_value(v, f"{w}.z[{n}]")
        frame = _array(b.get("frame", nodes[:3].tolist()), (3, 2), 'plane "frame"', w)
        if not _spans_plane(nodes):
            raise _fail(w, "plane nodes lie on a line: they do not define a plane",
                        hint="give corner points of a rectangle")
        if not _spans_plane(frame):
            raise _fail(w, "the plane's frame nodes lie on a line: they do not define a frame",
                        hint='give three corners of a triangle as "frame" (default: the first three nodes)')
        self._nodes, self._frame = nodes, frame

    def _check_calibration(self) -> None:
        from postproc.calfile import load_calibration

        b, w = self.body, self.where
        name = b.get("file")
        if not isinstance(name, str) or not name.strip():
            raise _fail(w, f'calibration needs a file name, got {name!r}',
                        hint='{"calibration": "my_machine.json"}, the path relative to the chain file')
        at = b.get("at", ["X", "Y", "Z"])
        if not isinstance(at, list) or len(at) != 3:
            raise _fail(w, f'calibration "at" must be three values (the commanded X, Y, Z), got {at!r}')
        for n, v in enumerate(at):
            check_value(v, f"{w}.at[{n}]")
        ctx = b.get("context", {})
        if not isinstance(ctx, Mapping):
            raise _fail(w, f'calibration "context" must map context names to values, got {ctx!r}')
        for key, v in ctx.items():
            check_value(v, f"{w}.context.{key}")
        path = Path(name) if self.base_dir is None else Path(self.base_dir) / name
        try:
            self._cal = load_calibration(path)
        except PostprocError as exc:
            place = f"{exc.place}: " if exc.place else ""
            raise type(exc)(f"{w}: calibration {place}{exc.message}", hint=exc.hint) from None
        missing = [c for c in self._cal.engine.needs if c not in ctx]
        if missing:
            raise _fail(w, f"the effects of calibration {name} need the context value(s) {missing}",
                        hint='map each to a value: "context": {' + ", ".join(f'"{c}": "{c}"' for c in missing)
                             + "}, and give the variables in the operation's \"context\"")
        self._at, self._ctx = list(at), dict(ctx)

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
        if self.kind == "calibration":
            return self._calibration_matrix(env)
        if self.kind == "linear":
            s = evaluate(b["var"], env, f"{w}.var") * self._scale
            return frames.translation_along(self._dir, s)
        if self.kind == "rotary":
            a = evaluate(b["var"], env, f"{w}.var") * self._scale
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

    def _calibration_matrix(self, env: Mapping[str, Any]) -> np.ndarray:
        """``[[A, t], [0, 1]]`` with ``F(q, r) = q + t + A r``, F the calibration's forward model."""
        w = self.where
        at = [evaluate(v, env, f"{w}.at[{n}]") for n, v in enumerate(self._at)]
        ctx = {k: evaluate(v, env, f"{w}.context.{k}") for k, v in self._ctx.items()}
        shape = np.broadcast_shapes(*(np.shape(a) for a in (*at, *ctx.values())))
        q = np.stack([np.broadcast_to(a, shape).ravel() for a in at], axis=1)
        context = {k: np.broadcast_to(v, shape).ravel() for k, v in ctx.items()} or None
        engine = self._cal.engine
        outside = ~engine.inside(q)
        if outside.any():
            lo, hi = engine.volume_mm
            raise _fail(w, f"commanded position {q[outside][0].round(4).tolist()} lies outside the calibrated "
                           f"volume {lo.tolist()}..{hi.tolist()} of {self.body['file']}",
                        hint="predict inside the volume the calibration was measured in")
        p0 = engine.forward(q, np.zeros_like(q), context)
        m = frames.identity(shape)
        m[..., :3, 3] = (p0 - q).reshape(shape + (3,))
        for i in range(3):
            lever = np.zeros_like(q)
            lever[:, i] = CALIBRATION_LEVER_MM
            col = (engine.forward(q, lever, context) - p0) / CALIBRATION_LEVER_MM
            m[..., :3, i] = col.reshape(shape + (3,))
        return m

    def variables(self) -> set[str]:
        b = self.body
        if self.kind == "fixed":
            return set()
        if self.kind == "calibration":
            return set().union(*(names_in(v) for v in (*self._at, *self._ctx.values())))
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
        if getattr(self, "_short", False) and set(self.body) == {"file"}:
            return {self.kind: self.body["file"]}
        return {self.kind: self.body}

    def turned_by(self, var: str) -> Element:
        """A spindle element as the rotation by the angle ``var`` (deg) in place of ``rpm`` and
        time: ``sign * var + phase``, the same direction and phase."""
        if self.kind != "spindle":
            return self
        sign = -1.0 if self.body.get("direction", "cw") == "cw" else 1.0
        angle = {"sum": [{"scale": sign * np.pi / 180.0, "of": var}, self.body.get("phase", 0.0)]}
        return Element("rotary", {"axis": self.body.get("axis", "z"), "var": angle, "unit": "rad"},
                       f"{self.where} (turned by {var})")


def _spans_plane(xy: np.ndarray) -> bool:
    """Whether 2-D points span a plane (are not all on one line), scale-free."""
    d = xy - xy.mean(axis=0)
    s = np.linalg.svd(d, compute_uv=False)
    return bool(s[0] > 0 and s[-1] > frames.COLLINEAR_RATIO * s[0])


@dataclass
class Module:
    """A named product of elements (one block of the machine)."""

    name: str
    elements: list[Element] = field(default_factory=list)

    def matrix(self, env: Mapping[str, Any]) -> np.ndarray:
        m = np.eye(4)
        for el in self.elements:
            e = el.matrix(env)
            if not np.all(np.isfinite(e)):
                raise _fail(el.where, "gives a matrix that is not finite (a value overflows for these variables)",
                            hint="check the element's values and the range of its variables")
            m = m @ e
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
    path: str | None = None  # the file it was read from, named in evaluation errors

    def matrix(self, env: Mapping[str, Any] | None = None) -> np.ndarray:
        """``M = M_1 ... M_m``: tool-frame -> workpiece-frame transforms, shape ``S + (4, 4)``."""
        env = {**self.defaults, **(env or {})}
        m = np.eye(4)
        try:
            for mod in self.modules:
                m = m @ mod.matrix(env)
        except PostprocError as exc:
            raise exc.at(self.path) from None
        return m

    def spindle_turned_by(self, var: str) -> Chain:
        """This chain with every ``spindle`` element turned by the angle ``var`` (deg)
        instead of ``rpm`` and time: a bore section samples the tool at spindle angles."""
        mods = [Module(m.name, [e.turned_by(var) for e in m.elements]) for m in self.modules]
        return replace(self, modules=mods)

    def has_spindle(self) -> bool:
        return any(e.kind == "spindle" for m in self.modules for e in m.elements)

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


#: Keys a chain file and a module may hold besides their content; "comment" and
#: "_comment" are free text (JSON has no comments).
COMMENT_KEYS = ("comment", "_comment")
CHAIN_KEYS = ("format", "version", "name", "description", "defaults", "random", "modules", *COMMENT_KEYS)
MODULE_KEYS = ("name", "elements", *COMMENT_KEYS)


def element_from_dict(data: Any, where: str, base_dir: Path | None = None) -> Element:
    if not isinstance(data, Mapping):
        raise _fail(where, f"an element must be an object like {{\"linear\": {{...}}}}, got {data!r}")
    keys = [k for k in data if k not in COMMENT_KEYS]
    if len(keys) != 1:
        raise _fail(where, f"an element has exactly one kind key, got {sorted(keys)}", hint=f"one of {', '.join(KINDS)}")
    return Element(keys[0], data[keys[0]], where, base_dir)


def chain_from_dict(data: Any, where: str = "chain", base_dir: Path | str | None = None) -> Chain:
    """Build a :class:`Chain` from its JSON description (see ``docs/predict.md``).

    ``base_dir``: where the files a chain names (calibrations) are found.
    """
    if not isinstance(data, Mapping) or data.get("format") != CHAIN_FORMAT:
        raise _fail(where, f'not a chain description: "format" must be "{CHAIN_FORMAT}"')
    if data.get("version", 1) != 1:
        raise _fail(where, f"chain version {data.get('version')!r} is not supported (this reads 1)")
    unknown = sorted(set(data) - set(CHAIN_KEYS))
    if unknown:
        raise _fail(where, f"unknown key(s) {unknown}", hint=f"a chain holds {', '.join(CHAIN_KEYS)}")
    mods = data.get("modules")
    if not isinstance(mods, list) or not mods:
        raise _fail(where, '"modules" must be a non-empty list')
    base = None if base_dir is None else Path(base_dir)
    modules = []
    for i, mod in enumerate(mods):
        w = f"{where}: modules[{i}]"
        if not isinstance(mod, Mapping) or not isinstance(mod.get("elements"), list):
            raise _fail(w, 'a module needs "name" and a list "elements"')
        unknown = sorted(set(mod) - set(MODULE_KEYS))
        if unknown:
            raise _fail(w, f"unknown key(s) {unknown}", hint=f"a module holds {', '.join(MODULE_KEYS)}")
        name = str(mod.get("name", f"module{i + 1}"))
        els = [element_from_dict(e, f"{w} ({name}).elements[{j}]", base) for j, e in enumerate(mod["elements"])]
        modules.append(Module(name, els))
    random = data.get("random", {})
    if not isinstance(random, Mapping):
        raise _fail(where, '"random" must be an object name -> distribution')
    from postproc.predict.tolerance import check_distribution

    for name, dist in random.items():
        check_distribution(dist, f"{where}: random.{name}")
    defaults = data.get("defaults", {})
    if not isinstance(defaults, Mapping) or not all(_is_number(v) for v in defaults.values()):
        raise _fail(where, '"defaults" must map variable names to finite numbers')
    return Chain(modules, str(data.get("name", "chain")), dict(random), str(data.get("description", "")),
                 {str(k): float(v) for k, v in defaults.items()})
