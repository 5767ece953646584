"""rgm: rapid geometric modeling.

Noisy 3-D scans become procedural CAD models written in the `.rgm` language, which the compiler
checks and evaluates and the back ends lower to IGES 5.3, Alpha_1-style text, STEP or meshes.

The public Python API is small and lazy: importing `rgm` imports neither numpy-heavy back ends nor
OpenCASCADE.

    model = rgm.load("examples/pin.rgm", params={"radius": 30})
    shape = rgm.to_cadquery(model)          # needs cadquery
"""
from __future__ import annotations

__version__ = "0.1.0"
__all__ = ["load", "loads", "to_cadquery", "__version__"]


def load(path, params=None):
    """Parse, check and evaluate an `.rgm` file into a `rgm.model.Model`.

    `params` overrides `param` bindings by name (values in model units, or strings such as "30mm").
    Raises `rgm.compiler.diagnostics.CompileError` carrying every diagnostic when the file has errors.
    """
    from rgm.compiler.api import load as _load

    return _load(path, params=params)


def loads(text, params=None, filename="<string>"):
    """As `load`, from source text."""
    from rgm.compiler.api import loads as _loads

    return _loads(text, params=params, filename=filename)


def to_cadquery(model):
    """Lower an evaluated model to CadQuery objects (imports cadquery/OCP on first use)."""
    from rgm.backends.occ import to_cadquery as _to_cadquery

    return _to_cadquery(model)
