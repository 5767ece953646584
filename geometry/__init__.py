"""rgm.geometry: the numeric NURBS core (numpy/scipy only; knows nothing of the language).

    from rgm.geometry import NurbsCurve, NurbsSurface

Modules: `basis` (vectorised basis functions, sparse basis matrices), `curve`, `surface`, `knots`
(insertion, refinement, splitting, degree elevation), `conics` (exact lines, arcs, circles, conics),
`revolve` (exact surfaces of revolution, extrusions, ruled surfaces, planes, composite curves),
`inversion` (closest points), `intersect` (surface/plane and surface/surface marching), `polygon`
(even-odd point-in-region tests of parameter-plane loops).
"""
from .basis import basis_matrix
from .curve import NurbsCurve
from .surface import NurbsSurface

__all__ = ["NurbsCurve", "NurbsSurface", "basis_matrix"]
