"""The postproc calibration file: JSON text, versioned, units explicit.

Layout (see the README, "Calibration file")::

    {
      "format": "postproc calibration",
      "version": 1,
      "method": "static",                 # engine name, see engine/registry.py
      "name": "s500-demo",                # free text, recorded in corrected programs
      "units": {"length": "mm", "angle": "rad"},
      "volume_mm": [[xmin, ymin, zmin], [xmax, ymax, zmax]],   # calibrated volume in q
      "model": {...},                     # method-specific parameters
      "effects": [{"name": "backlash:X", "params": {...}}, ...],  # optional
      "fit": {...},                       # optional: how it was made (rms, n_points, sources)
      "created_by": "postproc 0.1.0"
    }
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from postproc import __version__
from postproc.calibration.sniff import sniff
from postproc.constants import MAX_VOLUME_MM
from postproc.engine.base import Engine
from postproc.engine.registry import engine_class
from postproc.errors import CalibrationError, MeasurementError
from postproc.fileio import atomic_write_text, output_mode  # noqa: F401  (re-exported)

# Integers beyond this do not fit a float (1.8e308) and are refused as corrupt.
_LARGEST_INT = int(1.7e308)

FORMAT = "postproc calibration"
VERSION = 1
UNITS = {"length": "mm", "angle": "rad"}


@dataclass
class Calibration:
    engine: Engine
    name: str
    sha256: str = ""
    path: str | None = None
    effects: list = field(default_factory=list)
    fit: dict = field(default_factory=dict)

    @property
    def method(self) -> str:
        return self.engine.method


#: Largest number a calibration's model or effects may hold: 1 km in mm, a billion
#: iterations or cells. Anything larger is corrupt, and overflows the model's arithmetic.
MAX_MODEL_NUMBER = 1e9


def _check_finite(obj, path: str, where: str = "model", floats: bool = True, sized: bool = True) -> None:
    """Every number in the model must be finite: NaN or inf in a calibration is corrupt, and
    so is a number beyond :data:`MAX_MODEL_NUMBER` in size (an integer no float holds among
    them). Walked without recursion: the nesting of a JSON file is bounded by the reader,
    not by the interpreter's stack. ``floats``: NaN and inf are refused here (else by the
    reader of that part, in its words); ``sized``: the size bound applies (the volume has
    its own, :data:`postproc.constants.MAX_VOLUME_MM`)."""
    todo = [(obj, where)]
    while todo:
        obj, where = todo.pop()
        if isinstance(obj, dict):
            todo.extend((v, f"{where}.{k}") for k, v in obj.items())
        elif isinstance(obj, list):
            for i, v in enumerate(obj):
                if isinstance(v, (str, bool)) or v is None:  # numpy reads ["1", "0"] as numbers, true as 1
                    raise CalibrationError(f"{where}[{i}] is {json.dumps(v)}: the arrays of a calibration hold "
                                           "numbers (written without quotes)", path=path,
                                           hint="write the number itself, e.g. 1.0, not \"1.0\"")
            todo.extend((v, f"{where}[{i}]") for i, v in reversed(list(enumerate(obj))))  # the first named first
        elif isinstance(obj, float) and not math.isfinite(obj):
            if floats:
                raise CalibrationError(f"{where} is {obj}: a calibration must hold finite numbers", path=path)
        elif isinstance(obj, int) and not isinstance(obj, bool) and abs(obj) > _LARGEST_INT:
            raise CalibrationError(f"{where} is an integer of {len(str(abs(obj)))} digits: a calibration must hold "
                                   "numbers a float holds", path=path)
        elif sized and isinstance(obj, (int, float)) and not isinstance(obj, bool) and abs(obj) > MAX_MODEL_NUMBER:
            raise CalibrationError(f"{where} is {obj:.6g}: beyond any length (mm), angle (rad) or count a "
                                   f"calibration holds (at most {MAX_MODEL_NUMBER:g} in size)", path=path)


def calibration_to_dict(engine: Engine, *, name: str, effects=None, fit=None) -> dict:
    return {
        "format": FORMAT,
        "version": VERSION,
        "method": engine.method,
        "name": name,
        "units": dict(UNITS),
        "volume_mm": engine.volume_mm.tolist(),
        "model": engine.model_to_dict(),
        "effects": list(effects or []),
        "fit": dict(fit or {}),
        "created_by": f"postproc {__version__}",
    }


def save_calibration(path, engine: Engine, *, name: str | None = None, effects=None, fit=None) -> None:
    name = name or Path(path).stem
    text = json.dumps(calibration_to_dict(engine, name=name, effects=effects, fit=fit), indent=2)
    atomic_write_text(path, text + "\n")


def calibration_from_dict(data, *, path: str | None = None, sha256: str = "") -> Calibration:
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CalibrationError(
            "not a postproc calibration file (no \"format\": \"postproc calibration\")",
            path=path,
            hint="make one with 'postproc fit'",
        )
    if data.get("version") != VERSION:
        raise CalibrationError(
            f"calibration version {data.get('version')!r} is not supported (this postproc reads {VERSION})",
            path=path,
        )
    units = data.get("units")
    if units != UNITS:
        raise CalibrationError(
            f"calibration units {units!r}: expected {UNITS}",
            path=path,
            hint="calibration files hold lengths in mm and angles in rad; refit or convert it",
        )
    for key in ("method", "volume_mm", "model"):
        if key not in data:
            raise CalibrationError(f"calibration has no {key!r}", path=path)
    for key in ("volume_mm", "model", "effects"):
        _check_finite(data.get(key), path or "", key, floats=key != "effects", sized=key != "volume_mm")
    if not isinstance(data["method"], str):
        raise CalibrationError(f"calibration method {data['method']!r} is not a name", path=path)
    try:
        cls = engine_class(data["method"])
    except CalibrationError as exc:
        raise exc.at(path=path) from None
    try:
        engine = cls.model_from_dict(data["model"], data["volume_mm"])
    except CalibrationError as exc:
        raise exc.at(path=path) from None
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise CalibrationError(
            f"malformed {data['method']} model: {type(exc).__name__}: {exc}", path=path
        ) from None
    vol = engine.volume_mm
    if any(abs(v) > MAX_VOLUME_MM for corner in vol.tolist() for v in corner):
        raise CalibrationError(
            f"calibrated volume {vol.tolist()} mm reaches beyond {MAX_VOLUME_MM / 1000:g} m: no machine "
            "is that large, and such a volume switches the outside-volume check off", path=path,
            hint="volume_mm holds the measured travel in mm (a volume in um, or 1e308, is a mistake)")
    effects = data.get("effects") or []
    if effects:
        from postproc.effects import compose  # only calibrations with effects need them

        try:
            engine = compose(engine, effects)
        except CalibrationError as exc:
            raise exc.at(path=path) from None
        _check_effect_params(effects, path)
    return Calibration(
        engine=engine,
        name=str(data.get("name") or (Path(path).stem if path else "calibration")),
        sha256=sha256,
        path=path,
        effects=effects,
        fit=data.get("fit") or {},
    )


def _check_effect_params(effects, path: str | None) -> None:
    """Every effect a calibration lists gives each of its parameters: an effect without
    them would be read as zero, so the file would say "backlash" and correct none (a file
    cut short, or written by hand); ``fit`` writes them all."""
    from postproc.effects.registry import get_effect

    if not isinstance(effects, list):
        return  # compose names what is wrong with it
    for k, entry in enumerate(effects):
        if not isinstance(entry, dict) or "name" not in entry:
            continue  # idem
        params = entry.get("params")
        try:
            names = get_effect(entry["name"], config=entry.get("config")).param_names
        except (CalibrationError, TypeError, ValueError, AttributeError):
            continue  # idem
        missing = [n for n in names if not isinstance(params, dict) or n not in params]
        if missing:
            raise CalibrationError(
                f"effects[{k}] ({entry['name']}) does not give its parameter(s) {', '.join(missing)}: it would "
                "correct nothing", path=path,
                hint="give every parameter in its \"params\" (as 'postproc fit --effect' writes them), or "
                     "remove the effect")


def _json_limit(exc: Exception) -> str:
    """What a JSON text the parser could not take holds (the parser's own limits)."""
    if isinstance(exc, RecursionError):
        return "arrays or objects nested too deeply"
    return str(exc).split(";")[0]


def load_calibration(path) -> Calibration:
    path = str(path)
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise CalibrationError(f"cannot read calibration: {exc.strerror}", path=path) from None
    sha = hashlib.sha256(raw).hexdigest()
    try:
        data = json.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"calibration is not UTF-8 text ({exc.reason})", path=path) from None
    except RecursionError:  # arrays or objects nested thousands deep
        raise CalibrationError("calibration is not a calibration: its JSON nests too deep to be read",
                               path=path) from None
    except json.JSONDecodeError as exc:
        kind = _csv_kind(path)
        if kind:
            raise CalibrationError(
                f"this is a CSV file of {kind}, not a calibration",
                path=path,
                hint=f"make a calibration from it first: postproc fit {path} -o CAL.json, then give -c CAL.json",
            ) from None
        raise CalibrationError(f"calibration is not valid JSON: {exc.msg}", path=path, lineno=exc.lineno, col=exc.colno) from None
    except ValueError as exc:  # a number of over 4300 digits
        raise CalibrationError(f"calibration is not JSON postproc can read: {_json_limit(exc)}", path=path) from None
    return calibration_from_dict(data, path=path, sha256=sha)


def _csv_kind(path: str) -> str | None:
    """What formats.md file ``path`` holds (for a calibration given a CSV), else None."""
    names = {"measurements": "point measurements", "tables": "axis error tables", "squareness": "squareness",
             "runs": "ISO 230-2 interferometer runs", "isg": "TF5280 component errors"}
    try:
        return names[sniff(path)]
    except MeasurementError:
        return None
