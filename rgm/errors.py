"""One exception hierarchy for programmer and environment errors.

User mistakes in `.rgm` text are diagnostics (`rgm.compiler.diagnostics`), not exceptions.
"""


class RgmError(Exception):
    """Base class of rgm's own exceptions; the CLI prints its message without a traceback."""


class GeometryError(RgmError):
    """A geometric construction that cannot be carried out (degenerate input, no convergence)."""


class BackendError(RgmError):
    """A back end could not lower the model, or its written file failed verification."""
