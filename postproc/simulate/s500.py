"""The S500-like virtual machine shipped in ``calibrations/s500.machine.json``.

A three-axis machining centre with a 315 mm cube of travel and errors of the
magnitude reported for the STAN S500 (seed 000): uncorrected volumetric errors of
about 0.1-0.45 mm in the cube, of which an affine (static) model removes roughly
half. Each of the 18 error functions is a smooth sum of a linear term, a bow, a slow
guideway waviness and, on the positioning errors, a lead-screw periodic component
(10 mm pitch). Everything is deterministic: the functions below are the definition,
and :func:`write_s500` writes the files (``benchmarks/s500_demo.py``).

:func:`synthetic_tables` gives the tables of other smooth machines of the same
magnitudes (one per seed), for tests and demos; ``SEED_CONTROL_POINTS_MM`` are the
control points of seed 000's experiments.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from postproc.calibration.axis_tables import AXES, COLUMNS, AxisTables, Squareness
from postproc.calibration.tables import write_tables
from postproc.simulate.machine import Machine, MachineGeometry, Noise, save_machine

TRAVEL_MM = 315.0
TABLE_STEP_MM = 1.0  # fine enough that linear interpolation of the lead-screw term is exact to ~10 nm
SCREW_PITCH_MM = 10.0

#: Seed 000, Table 1: the ten control points (x_d/y_d/z_d, mm) of the S500 experiments.
SEED_CONTROL_POINTS_MM = (
    (230, 230, 230), (110, 170, 185), (170, 125, 200), (198, 196, 140), (130, 140, 106),
    (50, 50, 50), (133, 198, 176), (80, 112, 118), (162, 168, 210), (108, 136, 168),
)

# Per axis and column: (slope per mm, bow amplitude, waviness amplitude, waviness
# period mm, waviness phase rad, lead-screw amplitude). Lengths in mm, angles in rad.
# Bow is a parabola zero at both ends with this value in the middle.
_TERMS = {
    "X": {
        "EX": (0.000868, 0.12, 0.006, 140.0, 0.3, 0.0025),
        "EY": (-4e-05, 0.09, 0.004, 190.0, 1.1, 0.0),
        "EZ": (4e-05, -0.1, 0.005, 160.0, 2.0, 0.0),
        "EA": (0.0, 1.2e-05, 4e-06, 150.0, 0.5, 0.0),
        "EB": (1e-07, -2.5e-05, 6e-06, 170.0, 1.7, 0.0),
        "EC": (-8e-08, 3e-05, 5e-06, 130.0, 2.6, 0.0),
    },
    "Y": {
        "EX": (0.000392, -0.11, 0.005, 175.0, 0.9, 0.0),
        "EY": (0.001008, 0.14, 0.007, 120.0, 2.2, 0.002),
        "EZ": (-4e-05, 0.08, 0.004, 200.0, 0.1, 0.0),
        "EA": (1.2e-07, 2.8e-05, 5e-06, 140.0, 1.3, 0.0),
        "EB": (0.0, -1.5e-05, 4e-06, 180.0, 0.4, 0.0),
        "EC": (-6e-08, 2.2e-05, 6e-06, 110.0, 2.9, 0.0),
    },
    "Z": {
        "EX": (-0.00028, 0.1, 0.004, 165.0, 1.5, 0.0),
        "EY": (0.000308, -0.09, 0.005, 145.0, 0.7, 0.0),
        "EZ": (0.000784, 0.11, 0.006, 135.0, 2.4, 0.002),
        "EA": (-9e-08, 2e-05, 5e-06, 160.0, 0.2, 0.0),
        "EB": (7e-08, -2.6e-05, 4e-06, 125.0, 1.9, 0.0),
        "EC": (0.0, 1e-05, 3e-06, 190.0, 1.0, 0.0),
    },
}

#: Squareness (rad): Y to X, Z to X, Z to Y.
SQUARENESS = {"EC0Y": 3.6e-4, "EB0Z": -2.4e-4, "EA0Z": 3.0e-4}

#: Offset of the machine's actual origin from the tracker frame (mm): the whole
#: error at q = 0, as measured by a tracker referred to the ideal frame.
ORIGIN_OFFSET_MM = (0.045, -0.0375, 0.030)

#: Instrument noise (one sigma per reading). Tracker: per shot and coordinate, the seed
#: averaged 12 shots of an instrument certified to 15 um. Interferometer: table values.
NOISE = Noise(
    tracker_mm=0.005,
    interferometer_length_mm=0.0001,
    interferometer_angle_rad=1e-7,
    squareness_rad=3e-7,
)


def _column(s: np.ndarray, terms: tuple) -> np.ndarray:
    slope, bow, wave, period, phase, screw = terms
    u = s / TRAVEL_MM
    values = slope * s + bow * 4 * u * (1 - u)
    values += wave * (np.sin(2 * np.pi * s / period + phase) - np.sin(phase))
    values += screw * np.sin(2 * np.pi * s / SCREW_PITCH_MM)
    return values


def s500_tables(step_mm: float = TABLE_STEP_MM) -> AxisTables:
    """The 18 error functions tabulated every ``step_mm`` over the travel."""
    s = np.linspace(0.0, TRAVEL_MM, int(round(TRAVEL_MM / step_mm)) + 1)
    pos, err = {}, {}
    for axis, cols in _TERMS.items():
        values = np.column_stack([_column(s, cols[c]) for c in COLUMNS])
        if axis == "X":  # the origin offset is carried by the X table's linear columns
            values[:, :3] += ORIGIN_OFFSET_MM
        pos[axis], err[axis] = s, values
    return AxisTables(pos, err)


def s500_machine() -> Machine:
    """The S500-like machine, built in-process (same as calibrations/s500.machine.json)."""
    volume = [[0.0, 0.0, 0.0], [TRAVEL_MM] * 3]
    geometry = MachineGeometry(s500_tables(), SQUARENESS, volume, rotation="finite")
    return Machine(
        geometry=geometry,
        effects=[],
        noise=NOISE,
        name="s500",
        description=(
            "S500-like three-axis machining centre, 315 mm cube; 18 smooth error functions "
            "(linear + bow + waviness + 10 mm lead-screw term on positioning) and squareness; "
            "generated by postproc.simulate.s500"
        ),
    )


def write_s500(directory) -> list[Path]:
    """Write s500.machine.json with its tables and squareness files into ``directory``."""
    directory = Path(directory)
    machine = s500_machine()
    tables = directory / "s500_tables.csv"
    squareness = directory / "s500_tables_squareness.csv"
    write_tables(tables, squareness, machine.geometry.tables, machine.geometry.squareness,
                 comments=["S500-like virtual machine: true error functions (no noise)"])
    target = directory / "s500.machine.json"
    save_machine(target, machine, tables=tables.name, squareness=squareness.name)
    return [target, tables, squareness]


# -- a smooth machine of seed-000 magnitudes, for tests and demos ---------------------


def synthetic_tables(seed: int = 0, *, travel_mm: float = 315.0, step_mm: float = 15.0,
                     noise_mm: float = 0.0, noise_rad: float = 0.0) -> tuple[AxisTables, Squareness]:
    """Tables of a smooth machine with seed-000 magnitudes (STAN S500-like).

    Positioning errors of 0.9-1.3 mm/m with a slow bow and a few micrometres of
    waviness, straightness bows of 10-30 um, angular errors of 20-80 urad with some
    waviness, squareness of 100-300 urad: over a 315 mm cube with a 100 mm tool the
    uncorrected |error| is about 0.1-0.45 mm, as in seed 000, Table 1. Every function
    is zero at position 0 (where an interferometer run is zeroed). Optional Gaussian
    noise imitates the instrument.
    """
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, travel_mm + step_mm / 2, step_mm)
    s = x / travel_mm
    pos, err = {}, {}
    for k, ax in enumerate(AXES):
        cols = np.zeros((len(x), 6))
        for j in range(3):
            period = rng.uniform(40.0, 90.0)
            phase = rng.uniform(0, 2 * np.pi)
            wave = np.sin(2 * np.pi * x / period + phase) - np.sin(phase)
            if j == k:  # positioning: scale error, bow, waviness
                cols[:, j] = (rng.choice([-1, 1]) * rng.uniform(0.9e-3, 1.3e-3) * x
                              + rng.uniform(-20e-3, 20e-3) * s**2 + rng.uniform(1e-3, 4e-3) * wave)
            else:  # straightness: bow, small trend, waviness
                cols[:, j] = (rng.choice([-1, 1]) * rng.uniform(10e-3, 30e-3) * s**2
                              + rng.uniform(-3e-5, 3e-5) * x + rng.uniform(0.5e-3, 2e-3) * wave)
        for j in range(3, 6):
            period = rng.uniform(60.0, 150.0)
            phase = rng.uniform(0, 2 * np.pi)
            wave = np.sin(2 * np.pi * x / period + phase) - np.sin(phase)
            cols[:, j] = (rng.choice([-1, 1]) * rng.uniform(20e-6, 80e-6) * s
                          + rng.uniform(3e-6, 10e-6) * wave)
        if noise_mm or noise_rad:
            cols[1:, :3] += rng.normal(0.0, noise_mm, (len(x) - 1, 3))
            cols[1:, 3:] += rng.normal(0.0, noise_rad, (len(x) - 1, 3))
        pos[ax], err[ax] = x.copy(), cols
    sq = Squareness(*(rng.choice([-1, 1]) * rng.uniform(100e-6, 300e-6) for _ in range(3)))
    return AxisTables(pos, err), sq
