"""Predict machined surfaces and feature errors from a serial-chain machine model.

- :mod:`.frames`: 4x4 transforms, error matrices, frames from three points, planes;
- :mod:`.chain`: the machine as modules of elements, and its JSON description;
- :mod:`.tools`: cutting edges of mills and a boring tool;
- :mod:`.trace`: the trace of an edge and the surface it leaves (seed 002);
- :mod:`.tolerance`: Monte Carlo and worst case over tolerance fields (seed 004);
- :mod:`.bore`: the bored-hole example of seed 004.
"""

from postproc.predict.chain import Chain, Element, Module, chain_from_dict

__all__ = ["Chain", "Element", "Module", "chain_from_dict"]
