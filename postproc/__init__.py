"""postproc: correct CNC G-code programs for a machine's measured geometric errors."""

__version__ = "0.1.0"
