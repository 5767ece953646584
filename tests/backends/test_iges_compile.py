"""`rgmc compile -t iges` on the example models: --verify passes, the file reads back to the same
model, and `rgmc import` of it compiles to the same geometry."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from iges_model_strategies import assert_same_model
from rgm.backends.iges_read import read_iges_file
from rgm.backends.iges_verify import sample_object
from rgm.cli import main

EXAMPLES = sorted((Path(__file__).parents[2] / "examples").glob("*.rgm"))


@pytest.mark.occ
@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_compile_verify_read_import(path, tmp_path, capsys):
    pytest.importorskip("OCP")
    import rgm

    model = rgm.load(path)
    igs = tmp_path / "m.igs"
    assert main(["compile", str(path), "-t", "iges", "-o", str(igs), "--verify"]) == 0, capsys.readouterr().err
    back = read_iges_file(igs)
    assert back.ok
    lazy = any("intersect" in line for line in path.read_text().splitlines())
    if not lazy:  # lazy intersections come back as their approximation (B-splines), by design
        assert_same_model(model, back.model)
    out = tmp_path / "m.rgm"
    assert main(["import", str(igs), "-o", str(out)]) == 0
    again = rgm.load(out)
    size = 1000.0
    for name in back.model.exports:
        a = sample_object(back.model.objects[name], model.tolerance)  # the file's geometry
        b = sample_object(again.objects[name], model.tolerance)
        assert a.shape == b.shape and np.abs(a - b).max() <= 1e-9 * size
