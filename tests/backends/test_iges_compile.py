"""`rgmc compile -t iges` on the example models: --verify passes, the file reads back to the same
model (lazy intersections as their approximation), OpenCASCADE reads it matching rgm's evaluation
within 1e-9 x the model size, and `rgmc import` of it compiles to the same geometry."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from iges_model_strategies import assert_opencascade_reads, assert_same_model
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
    assert_same_model(model, back.model, approximated=model.tolerance)   # lazy intersections: approximated
    assert_opencascade_reads(model, igs)
    out = tmp_path / "m.rgm"
    assert main(["import", str(igs), "-o", str(out)]) == 0
    again = rgm.load(out)
    size = 1000.0
    for name in back.model.exports:
        a = sample_object(back.model.objects[name], model.tolerance)  # the file's geometry
        b = sample_object(again.objects[name], model.tolerance)
        assert a.shape == b.shape and np.abs(a - b).max() <= 1e-9 * size
