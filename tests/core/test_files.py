"""Writing files (files.py): atomic writes leave no temporary and a readable file; the JSON
writer's values are always valid JSON (no NaN or Infinity), numpy included."""

from __future__ import annotations

import json
import math
import os

import numpy as np
from hypothesis import given

from helpers import FAST, JSON_VALUES
from scanplan.core.files import dumps_json


def test_atomic_write_leaves_no_temporary_and_a_readable_file(tmp_path):

    from scanplan.core.files import atomic_write_text

    old = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "out.txt", "hello\n")
    finally:
        os.umask(old)
    assert (tmp_path / "out.txt").read_text() == "hello\n"
    assert (tmp_path / "out.txt").stat().st_mode & 0o777 == 0o644  # not mkstemp's 0600
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


@FAST
@given(value=JSON_VALUES)
def test_json_safe_always_gives_valid_json(value):
    text = dumps_json(value)

    def refuse(literal: str) -> None:
        raise AssertionError(f"{literal} in {text}")

    json.loads(text, parse_constant=refuse)  # no NaN/Infinity literal anywhere


def test_json_safe_on_numpy():
    out = json.loads(dumps_json({"a": np.array([1.0, np.nan]), "b": np.int64(3), "c": math.inf}))
    assert out == {"a": [1.0, None], "b": 3, "c": None}
