"""`scanplan part`: a built-in part written as a mesh; an unknown name in one line."""

from __future__ import annotations

import pytest
import trimesh

from helpers import run_cli


def test_part_writes_a_builtin_mesh(tmp_path):
    out = tmp_path / "tp.stl"
    result = run_cli("part", "training-piece", "-o", str(out))
    assert result.exit_code == 0, result.output
    mesh = trimesh.load(out)
    assert mesh.extents == pytest.approx([1050, 150, 50], rel=0.02)


def test_part_unknown_name_is_one_line(tmp_path):
    out = tmp_path / "x.stl"
    result = run_cli("part", "teapot", "-o", str(out))
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0
    assert "unknown part 'teapot'" in result.output
    assert not out.exists()
