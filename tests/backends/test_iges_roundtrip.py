"""Model → IGES → model: rgm's reader gives back the same model, and OpenCASCADE's IGESControl_Reader
reads every file (all roots transferred, no fail message) with faces and edges matching rgm's own
evaluation within 1e-9 x the model size; with the default options (`pcurve_preference="auto"`)."""
from __future__ import annotations

import importlib.util
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from iges_model_strategies import KINDS, assert_opencascade_reads, assert_same_model, make_object, models
from rgm.backends.iges import iges_text, write_iges
from rgm.backends.iges_read import read_iges
from rgm.model import Model

OCC = importlib.util.find_spec("OCP") is not None
SETTINGS = settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                           HealthCheck.function_scoped_fixture])
COLOURS = st.one_of(st.none(), st.tuples(*[st.integers(0, 100).map(float)] * 3))


def _assert_round_trip(model, path, **options):
    """Write `model`, read it back with rgm (the same model) and with OpenCASCADE (the same geometry)."""
    write_iges(model, path, **options)
    back = read_iges(path.read_text())
    assert back.ok, back.messages()
    assert_same_model(model, back.model, approximated=model.tolerance)
    for name in model.objects:  # nested named pieces come back as bindings too
        assert name in back.model.objects
    if OCC:
        assert_opencascade_reads(model, path)


@SETTINGS
@given(model=models(), colour=COLOURS)
def test_model_iges_model_is_identical_and_opencascade_agrees(tmp_path, model, colour):
    _assert_round_trip(model, tmp_path / "m.igs", color=colour)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", [0, 1])
def test_every_kind_round_trips(tmp_path, kind, seed):
    """Each kind on its own (the hypothesis draws mix them), in mm and inches."""
    rng = np.random.default_rng(seed)
    obj = make_object(kind, rng, "x", 1e-3)
    _assert_round_trip(Model(("mm", "in")[seed], 1e-3, {"x": obj}, ("x",)), tmp_path / "k.igs")


@settings(max_examples=10, deadline=None)
@given(models())
def test_output_is_deterministic_and_80_columns(model):
    os.environ["SOURCE_DATE_EPOCH"] = "1700000000"
    try:
        a, b = iges_text(model), iges_text(model)
    finally:
        del os.environ["SOURCE_DATE_EPOCH"]
    assert a == b
    assert "20231114.221320" in a
    assert all(len(line) == 80 for line in a.splitlines())
