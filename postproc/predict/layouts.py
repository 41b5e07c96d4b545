"""Starting chains for ``postproc predict init``: the common modules of two machine layouts.

Each is a chain description (``docs/predict.md``) with a ``"comment"`` on every element
and module saying what it stands for and what to put there; JSON has no comments, and
the chain format keeps ``"comment"`` and ``"_comment"`` keys as free text.

- ``vertical-mill``: workpiece -> X table -> Y saddle -> Z head -> spindle (about z),
  the effective 3-axis model of formats.md (tool point relative to the workpiece);
  each axis is seed 002's ``M_D M_V``: its error motions (zero, to be filled in) and
  its travel.
- ``horizontal-boring``: seed 004's structure: workpiece -> bed -> guide plane of the
  spindle head (a plane through four corners inside a parallelism field, random) ->
  head travel along x -> spindle (about x) at the nose.

With a calibration the axes' error elements give way to one ``calibration`` element:
the volumetric error the calibration measured, at the commanded X, Y, Z.
"""

from __future__ import annotations

from postproc.predict.chain import CHAIN_FORMAT

LAYOUTS = ("vertical-mill", "horizontal-boring")

ZERO_ERROR_COMMENT = ("error motions of this axis (seed 002's M_D): u, v, w in mm, alpha, beta, gamma in rad; "
                      "each a number, a variable, or a function of the axis position such as "
                      '{"var": "%s", "table": {"positions": [0, 500], "values": [0, 0.004]}}')


def _axis(name: str, axis: str, var: str, with_errors: bool) -> dict:
    elements = []
    if with_errors:
        elements.append({"error": {"u": 0, "v": 0, "w": 0, "alpha": 0, "beta": 0, "gamma": 0},
                         "comment": ZERO_ERROR_COMMENT % var})
    elements.append({"linear": {"axis": axis, "var": var},
                     "comment": f"travel of {name}: the commanded {var} in mm"})
    return {"name": name, "_comment": f"{name}: {'error motions, then ' if with_errors else ''}travel",
            "elements": elements}


#: Value a context variable of the calibration's effects starts at in the chain's
#: defaults: an approach direction (dirx, diry, dirz) of +1, anything else 0.
DIRECTION_CONTEXT = ("dirx", "diry", "dirz")


def context_defaults(needs) -> dict[str, float]:
    """Defaults of the context variables a calibration's effects read (backlash: dirx ...)."""
    return {c: 1.0 if c in DIRECTION_CONTEXT else 0.0 for c in needs}


def _calibration_module(calibration: str, needs=()) -> dict:
    block: dict = {"file": calibration, "at": ["X", "Y", "Z"]}
    comment = ("path relative to this chain file; the calibration's forward model "
               "(with its effects) gives the error and the tilt of the tool at (X, Y, Z)")
    if needs:
        block["context"] = {c: c for c in needs}
        comment += (f"; its effects read {', '.join(needs)} (the approach direction, +1 or -1, for "
                    "dirx/diry/dirz): variables of that name, set in the defaults or an operation's context")
    return {"name": "measured machine",
            "_comment": "the volumetric error measured by postproc fit, at the commanded X, Y, Z",
            "elements": [{"calibration": block, "comment": comment}]}


def vertical_mill(calibration: str | None = None, centre_mm=(0.0, 0.0, 0.0), needs=()) -> dict:
    """A 3-axis vertical mill; with ``calibration`` its measured error in place of the axis errors."""
    modules = [
        {"name": "table and fixture", "_comment": "the workpiece frame",
         "elements": [{"fixed": {"translation": [0, 0, 0]},
                       "comment": "workpiece origin on the table; a fixture offset or tilt goes here"}]},
        _axis("X axis", "x", "X", calibration is None),
        _axis("Y axis", "y", "Y", calibration is None),
        _axis("Z axis", "z", "Z", calibration is None),
    ]
    if calibration is not None:
        modules.append(_calibration_module(calibration, needs))
    modules.append({"name": "spindle", "_comment": "the tool turns about z",
                    "elements": [{"spindle": {"axis": "z", "rpm": "rpm", "var": "t", "direction": "cw"},
                                  "comment": "M03 at rpm (variable), time t in s; a bore turns it by its "
                                             "section angle S instead. Tool points are given in this frame: "
                                             "a 100 mm tool hanging down ends at [0, 0, -100]"}]})
    return {
        "format": CHAIN_FORMAT,
        "version": 1,
        "name": "vertical mill",
        "description": "Workpiece -> X table -> Y saddle -> Z head -> spindle -> tool: the effective 3-axis "
                       "model, tool point relative to the workpiece (formats.md signs). Lengths mm, angles rad.",
        "_comment": "Edit the error elements (or give a calibration with predict init --calibration); "
                    "variables X, Y, Z, rpm and t come from an operation's context or these defaults.",
        "defaults": {"X": float(centre_mm[0]), "Y": float(centre_mm[1]), "Z": float(centre_mm[2]),
                     "rpm": 0.0, "t": 0.0, **context_defaults(needs)},
        "modules": modules,
    }


def horizontal_boring(calibration: str | None = None, centre_mm=(0.0, 0.0, 0.0), needs=()) -> dict:
    """A horizontal boring machine after seed 004 (sizes are examples to replace)."""
    modules = [
        {"name": "table and fixture", "_comment": "the workpiece frame: x along the spindle, z up",
         "elements": [{"fixed": {"translation": [0, 0, 0]},
                       "comment": "workpiece origin on the bed; a fixture error goes here"}]},
        {"name": "bed: guide plane of the spindle head",
         "_comment": "seed 004's M_O M_Gamma: nominal layout, then the guide plane inside its tolerance field",
         "elements": [
             {"fixed": {"translation": [0, 0, 300]},
              "comment": "M_O: the guides 300 mm above the workpiece frame (example size)"},
             {"plane": {"nodes": [[0, 0], [500, 0], [0, 400], [500, 400]], "z": ["g1", "g2", "g3", "g4"]},
              "comment": "M_Gamma: least-squares plane through the guides' corners, heights g1..g4 drawn "
                         "inside the parallelism field (random)"}]},
        _axis("head travel", "x", "X", calibration is None),
    ]
    if calibration is not None:
        modules.append(_calibration_module(calibration, needs))
    modules.append({"name": "spindle", "_comment": "the nose on the spindle axis; the tool turns about x",
                    "elements": [
                        {"fixed": {"translation": [500, 200, 260]},
                         "comment": "spindle nose: 500 mm along the guides, 200 mm across, 260 mm above them "
                                    "(example sizes)"},
                        {"spindle": {"axis": "x", "rpm": "rpm", "var": "t", "direction": "cw"},
                         "comment": "a bore turns it by its section angle S; the tool tip is at "
                                    "[overhang, radius, 0] in this frame"}]})
    return {
        "format": CHAIN_FORMAT,
        "version": 1,
        "name": "horizontal boring machine",
        "description": "Workpiece -> bed -> guide plane of the spindle head (inside a 0.05 mm parallelism "
                       "field) -> head travel along x -> spindle about x -> tool (seed 004's structure). "
                       "Sizes are examples: replace them with the machine's. Lengths mm, angles rad.",
        "_comment": "random: the guide corners' heights g1..g4 anywhere in the 0.05 mm field; set a "
                    "field to [0, 0] (or remove the plane) for a machine of known errors.",
        "defaults": {"X": float(centre_mm[0]), "rpm": 0.0, "t": 0.0,
                     **({"Y": float(centre_mm[1]), "Z": float(centre_mm[2])} if calibration else {}),
                     **context_defaults(needs)},
        "random": {name: {"uniform": [0, 0.05]} for name in ("g1", "g2", "g3", "g4")},
        "modules": modules,
    }


def layout_chain(layout: str, calibration: str | None = None, centre_mm=(0.0, 0.0, 0.0), needs=()) -> dict:
    """The starting chain of ``layout`` (one of :data:`LAYOUTS`) as JSON data; ``needs``: the
    context variables the calibration's effects read (a calibration from runs has
    backlash effects reading dirx ...), mapped to chain variables of the same name."""
    makers = {"vertical-mill": vertical_mill, "horizontal-boring": horizontal_boring}
    return makers[layout](calibration, centre_mm, tuple(needs))
