"""The perturbation model: its grammar, seeded draws, and zero terms that change nothing."""

from __future__ import annotations

import numpy as np
import pytest

from scanplan.sensor.perturb import Perturbation, Spread, rotation_matrix


def test_parse_reads_every_term_and_round_trips():
    m = Perturbation.parse("place:2mm,1deg; warp:1mm@200mm;scale:0.1%;path:±0.1mm,0.05deg")
    assert m.place_mm == Spread(2.0) and m.place_deg == Spread(1.0)
    assert (m.warp_mm, m.warp_wavelength_mm) == (1.0, 200.0)
    assert m.scale.size == pytest.approx(0.001)
    assert m.path_mm == Spread(0.1, uniform=True) and m.path_deg == Spread(0.05)
    assert Perturbation.parse(m.text()) == m
    assert Perturbation.parse("place:0mm,0deg;warp:0mm@200mm;path:0mm").is_zero


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "is empty"),
        ("place:2", "'place:2': expected a length"),
        ("warp:1mm", "'warp:1mm': expected an RMS amplitude and a wavelength"),
        ("warp:1mm@0mm", r"the wavelength 0mm is not in \[0.001, 100000\] mm"),
        ("twist:1deg", "unknown term 'twist'"),
        ("path:1mm;path:2mm", "'path' given twice"),
        ("scale:2", "expected a percentage"),
    ],
)
def test_bad_specs_are_one_line_errors(text, message):
    with pytest.raises(ValueError, match=message) as err:
        Perturbation.parse(text)
    assert "\n" not in str(err.value)


HUGE = "1" * 400  # parses as inf


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (f"place:{HUGE}mm", r"'place:1+\.\.\.': the length a number of 400 digits is not in"),
        ("place:1001mm", r"the length 1001mm is not in \[0, 1000\] mm"),
        ("place:2m", r"the length 2m is not in \[0, 1000\] mm"),
        ("place:2mm,181deg", r"the angle 181deg is not in \[0, 180\] deg"),
        (f"path:1mm,{HUGE}deg", "the angle a number of 400 digits"),
        (f"warp:{HUGE}mm@200mm", "the amplitude a number of 400 digits"),
        (f"warp:1mm@{HUGE}mm", "the wavelength a number of 400 digits"),
        ("warp:1mm@200m", r"the wavelength 200m is not in \[0.001, 100000\] mm"),
        ("scale:±20%", r"the scale error 20% is not in \[0, 10\] %"),
        (f"{HUGE}:1mm", r"unknown term '1{37}\.\.\.'"),
    ],
)
def test_implausible_magnitudes_name_the_term_and_range(text, message):
    with pytest.raises(ValueError, match=message) as err:
        Perturbation.parse(text)
    assert str(err.value).startswith("--perturb")
    assert "\n" not in str(err.value) and len(str(err.value)) < 200


def test_the_ends_of_the_ranges_parse():
    m = Perturbation.parse("place:1m,180deg;warp:1000mm@0.001mm;scale:10%;path:0mm,0deg")
    assert (m.place_mm.size, m.place_deg.size, m.warp_mm) == (1000.0, 180.0, 1000.0)
    assert (m.warp_wavelength_mm, m.scale.size) == (0.001, 0.1)


def test_draws_are_seeded_and_zero_terms_change_nothing():
    rng = np.random.default_rng(1)
    vertices, normals = rng.normal(size=(50, 3)) * 100, np.tile([0.0, 0.0, 1.0], (50, 1))
    poses = np.tile(np.eye(4), (5, 1, 1))
    m = Perturbation.parse("place:2mm,1deg;warp:1mm@200mm;scale:0.1%;path:0.1mm,0.1deg")
    a, b = m.trial(3, 7), m.trial(3, 7)
    centre = np.zeros(3)
    assert np.array_equal(
        a.as_built(vertices, normals, centre), b.as_built(vertices, normals, centre)
    )
    assert np.array_equal(a.path_poses(poses), b.path_poses(poses))
    assert not np.array_equal(a.T_part_placed(centre), m.trial(3, 8).T_part_placed(centre))
    R = a.T_part_placed(centre)[:3, :3]
    assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
    zero = Perturbation.parse("place:0mm,0deg;warp:0mm@200mm;path:0mm").trial(3, 7)
    assert np.array_equal(zero.as_built(vertices, normals, centre), vertices)
    assert zero.path_poses(poses) is poses
    assert np.array_equal(zero.T_part_placed(centre), np.eye(4))


def test_warp_has_the_amplitude_as_rms_and_is_smooth():
    m = Perturbation.parse("warp:1mm@200mm")
    grid = np.stack(np.meshgrid(*[np.linspace(0, 2000, 30)] * 2, [0.0]), -1).reshape(-1, 3)
    rms = np.mean([np.sqrt(np.mean(m.trial(0, i).warp_mm(grid) ** 2)) for i in range(20)])
    assert rms == pytest.approx(1.0, rel=0.15)
    # Within 1 mm of a point the field changes by at most 2π·amplitude·√(2m)/λ · 1 mm.
    d = m.trial(0, 0).warp_mm(grid + [1.0, 0, 0]) - m.trial(0, 0).warp_mm(grid)
    assert np.abs(d).max() < 2 * np.pi * 4.0 / 200.0


def test_rotation_matrix_turns_about_its_vector():
    R = rotation_matrix(np.array([0.0, 0.0, np.pi / 2]))
    assert np.allclose(R @ [1.0, 0, 0], [0, 1.0, 0])
    assert np.array_equal(rotation_matrix(np.zeros(3)), np.eye(3))
