"""Parts named with their units: PATH:UNITS, a list's 'PATH [UNITS]' lines, folders."""

from __future__ import annotations

import pytest
import trimesh

from scanplan.world.part_list import (
    PartRef,
    expand_parts,
    parse_list_line,
    parse_part,
    read_part_list,
)


def test_a_part_takes_its_units_after_a_colon_only_when_they_are_units():
    assert parse_part("door") == PartRef("door", "door", None)
    assert parse_part("/x/car.obj:m") == PartRef("/x/car.obj", "/x/car.obj", "m")
    assert parse_part("c:/parts/a.stl") == PartRef("c:/parts/a.stl", "c:/parts/a.stl", None)
    assert parse_part("a.stl:in").units_or("mm") == "in"
    assert parse_part("a.stl").units_or("m") == "m"


def test_a_list_line_takes_units_after_a_space_or_a_colon():
    assert parse_list_line("  # only a comment") is None
    assert parse_list_line("") is None
    assert parse_list_line("bracket.stl in  # inches") == PartRef(
        "bracket.stl", "bracket.stl", "in"
    )
    assert parse_list_line("my part.stl") == PartRef("my part.stl", "my part.stl", None)
    assert parse_list_line("door.obj:m").units == "m"
    with pytest.raises(ValueError, match="units 'inch': use one of mm, m, in"):
        parse_list_line("bracket.stl inch")


def test_a_list_resolves_paths_beside_it_and_names_its_bad_line(tmp_path):
    trimesh.creation.box((10, 10, 1)).export(tmp_path / "plate.stl")
    listing = tmp_path / "parts.txt"
    listing.write_text("plate.stl m\ndoor\n")
    plate, door = read_part_list(listing)
    assert plate == PartRef("plate.stl", str(tmp_path / "plate.stl"), "m")
    assert door == PartRef("door", "door", None)  # a built-in part, left to load_part
    listing.write_text("plate.stl\nplate.stl furlongs\n")
    with pytest.raises(ValueError, match=r"parts.txt, line 2: 'plate.stl furlongs'"):
        read_part_list(listing)


def test_arguments_expand_to_every_part_once(tmp_path):
    folder = tmp_path / "cad"
    folder.mkdir()
    for name in ("a.stl", "b.obj"):
        trimesh.creation.box((10, 10, 1)).export(folder / name)
    (tmp_path / "list.txt").write_text("c.stl in\n")
    refs = expand_parts([str(folder), str(tmp_path / "list.txt"), "door:m"])
    assert [(r.stem, r.units) for r in refs] == [
        ("a", None),
        ("b", None),
        ("c", "in"),
        ("door", "m"),
    ]
    with pytest.raises(ValueError, match="parts a would share a plan name"):
        expand_parts([str(folder), str(folder / "a.stl")])
