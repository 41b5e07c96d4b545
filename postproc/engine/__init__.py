"""Compensation engines: forward models ``p = F(q, r)`` and their inverses (pure numpy)."""

from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors

__all__ = ["Engine", "InverseResult", "check_points", "check_tool_vectors"]
