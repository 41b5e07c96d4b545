"""The virtual machine used by simulate, verify, demos and tests.

``load_machine(path) -> Machine`` reads a machine definition; :mod:`.points` makes
tracker measurements, :mod:`.tables` interferometer tables, :mod:`.verify` runs
programs and control points through a machine.
"""

from postproc.simulate.machine import (
    Machine,
    MachineError,
    MachineGeometry,
    Noise,
    load_machine,
    machine_from_dict,
    save_machine,
)
from postproc.simulate.points import (
    grid_points,
    measurement_plan,
    random_points,
    simulate_plan,
    simulate_points,
    static_set,
)

__all__ = [
    "Machine",
    "MachineError",
    "MachineGeometry",
    "Noise",
    "grid_points",
    "load_machine",
    "machine_from_dict",
    "measurement_plan",
    "random_points",
    "save_machine",
    "simulate_plan",
    "simulate_points",
    "static_set",
]
