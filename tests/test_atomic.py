"""Outputs are written atomically: complete or absent, never half-written; inputs are not overwritten."""
import os
import stat

import pytest

from rgm.atomic import OutputExists, temp_path_beside, write_atomic


def test_write_replaces_whole_file_with_normal_permissions(tmp_path):
    target = tmp_path / "sub" / "out.txt"
    write_atomic(target, "old")
    write_atomic(target, b"new bytes")
    assert target.read_bytes() == b"new bytes"
    mode = stat.S_IMODE(target.stat().st_mode)
    umask = os.umask(0)
    os.umask(umask)
    assert mode == 0o666 & ~umask
    assert [p.name for p in target.parent.iterdir()] == ["out.txt"]  # no temporary left behind


def test_refuses_to_overwrite_when_asked_not_to(tmp_path):
    target = tmp_path / "in.rgm"
    target.write_text("keep me")
    with pytest.raises(OutputExists, match="--force"):
        write_atomic(target, "clobber", overwrite=False)
    assert target.read_text() == "keep me"


def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.txt"
    target.write_text("old")

    class Boom:
        def __len__(self):
            raise RuntimeError("disk on fire")

    with pytest.raises(TypeError):
        write_atomic(target, Boom())
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_temp_path_beside_is_in_the_same_folder(tmp_path):
    p = temp_path_beside(tmp_path / "model.step")
    assert p.parent == tmp_path and p.suffix == ".step" and p.exists()
