"""`scanplan part`: write a built-in procedural part as a mesh file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from scanplan.cli.common import user_errors

MeshOutOpt = Annotated[
    Path,
    typer.Option(
        "-o",
        "--output",
        metavar="FILE",
        help="output file: the mesh (.stl, .ply, .obj, ...), in mm",
    ),
]


@user_errors
def part_cmd(
    name: Annotated[str, typer.Argument(help="door, drone or training-piece")],
    output: MeshOutOpt,
):
    """Write a built-in procedural part as a mesh file (STL, PLY, OBJ, ...)."""
    # Deferred: parts load trimesh and Embree.
    from scanplan.core.files import atomic_write_bytes
    from scanplan.world.part import load_part
    from scanplan.world.parts import PART_NAMES

    if name not in PART_NAMES:
        raise ValueError(f"unknown part {name!r}; built-in parts: {', '.join(PART_NAMES)}")
    part = load_part(name)
    file_type = output.suffix.lower().lstrip(".") or "stl"
    try:
        data = part.mesh.export(file_type=file_type)
    except (ValueError, KeyError, NotImplementedError):
        raise ValueError(
            f"cannot write mesh format {output.suffix!r}; use .stl, .ply or .obj"
        ) from None
    if not isinstance(data, bytes | str):
        raise ValueError(f"cannot write mesh format {output.suffix!r}; use .stl, .ply or .obj")
    atomic_write_bytes(output, data if isinstance(data, bytes) else data.encode())
    e = part.extents
    typer.echo(
        f"{name}: {len(part.mesh.faces)} triangles, {e[0]:.0f} x {e[1]:.0f} x {e[2]:.0f} mm "
        f"-> {output}"
    )
