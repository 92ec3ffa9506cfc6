"""STEP input (SPEC §6): the file's unit honoured, sizes and volumes right, bad files one line.

The fixtures under tests/data are made by tests/data/make_step_fixtures.py (gmsh's
OpenCASCADE); the volumes below are analytic.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from scanplan.part import load_part
from scanplan.pipeline import plan_path
from scanplan.planners import make_planner
from scanplan.quantities import ScanSpec
from scanplan.sensor import SensorSpec
from scanplan.swaths import plan_swaths

DATA = Path(__file__).parent / "data"


def _rounded_box_volume(a: float, b: float, c: float, r: float) -> float:
    """A box with every edge and corner rounded to radius r."""
    x, y, z = a - 2 * r, b - 2 * r, c - 2 * r
    return (
        x * y * z
        + 2 * r * (x * y + y * z + x * z)
        + math.pi * r * r * (x + y + z)
        + (4 / 3 * math.pi * r**3)
    )


@pytest.mark.parametrize(
    ("name", "extents", "volume"),
    [
        ("box", (200, 100, 50), 200 * 100 * 50),
        ("filleted_box", (120, 80, 40), _rounded_box_volume(120, 80, 40, 10)),
        ("plate_with_holes", (300, 200, 10), 300 * 200 * 10 - 4 * math.pi * 15**2 * 10),
        ("small_box_in", (3 * 25.4, 2 * 25.4, 25.4), 6 * 25.4**3),  # the file is in inches
        ("small_box_m", (3000, 2000, 1000), 6e9),  # the file is in metres
    ],
)
def test_step_parts_load_in_mm_with_the_right_size_and_volume(name, extents, volume):
    part = load_part(DATA / f"{name}.step")
    assert part.extents == pytest.approx(extents, rel=1e-6)
    assert part.mesh.is_watertight
    assert part.mesh.volume == pytest.approx(volume, rel=1e-3)
    assert (part.mesh.area_faces > 0).all()  # degenerate triangles dropped


def test_step_units_option_does_not_rescale_a_step_file():
    # The STEP file carries its own unit; --units is for unit-less mesh formats.
    assert load_part(DATA / "box.step", units="in").extents == pytest.approx((200, 100, 50))


def test_tessellation_is_bounded_by_the_part_size():
    # Deflection max(0.01 mm, 1e-3 x diagonal) and 0.2 rad: the fillets stay a small mesh.
    part = load_part(DATA / "filleted_box.step")
    assert len(part.mesh.faces) < 20_000


@pytest.mark.parametrize(
    "content",
    [b"", b"ISO-10303-21;\nHEADER;\nnot really\n", bytes(range(256)) * 4, b"\xff\xfe\x00\x00"],
)
@pytest.mark.parametrize("suffix", [".step", ".stp"])
def test_corrupt_or_empty_step_is_one_line(tmp_path, capfd, content, suffix):
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(content)
    with pytest.raises(ValueError) as err:
        load_part(path)
    message = str(err.value)
    assert str(path) in message and "\n" not in message
    out, errors = capfd.readouterr()
    assert out == "" and errors == ""  # OpenCASCADE's own complaints are not printed


def test_a_step_part_can_be_planned():
    part = load_part(DATA / "plate_with_holes.step")
    spec = SensorSpec().without_noise().with_points(64)
    swaths = plan_swaths(part, spec)
    traj = plan_path(part, ScanSpec(spec), make_planner("fixed"), swaths)
    assert len(swaths) == 1 and traj.scanning.sum() > 100
    assert np.isfinite(traj.poses).all()
    # the fixed planner flies at W_d above the plate's top face (z = 10 mm)
    assert np.median(traj.positions_mm[traj.scanning, 2]) == pytest.approx(410.0, abs=1.0)
