"""The ideal machine: p = q + r. Used for round-trip checks and as a neutral calibration."""

from __future__ import annotations

import numpy as np

from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors


class IdentityEngine(Engine):
    method = "identity"
    affine = True

    def forward(self, q, r=None, context=None) -> np.ndarray:
        q = check_points(q, "q")
        return q + check_tool_vectors(r, len(q))

    def inverse(self, p, r=None, context=None) -> InverseResult:
        p = check_points(p, "p")
        q = p - check_tool_vectors(r, len(p))
        return InverseResult(q, np.zeros(len(p)), np.zeros(len(p), dtype=int))

    def model_to_dict(self) -> dict:
        return {}

    @classmethod
    def model_from_dict(cls, model: dict, volume_mm) -> IdentityEngine:
        return cls(volume_mm)
