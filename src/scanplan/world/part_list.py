"""How a part is named with its units — `PATH:UNITS` on the command line, `PATH UNITS` on a
line of a list file (units optional either way) — and the list files and folders of parts
that `plan` and `compare` read: one parser for every command.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from scanplan.core.paths import read_regular
from scanplan.world.mesh_files import MESH_SUFFIXES, STEP_SUFFIXES, UNITS_TO_MM

# A list of parts is a text file rather than a part file: a .txt is no mesh.
PART_LIST_SUFFIX = ".txt"
# A list of parts, one a line: tens of thousands of lines at most.
MAX_PART_LIST_BYTES = 16 * 1024**2


@dataclass(frozen=True)
class PartRef:
    """A part to load: `source` (a file or a built-in part's name), its `units` (None: the
    command's --units), and `name`, as the user wrote it (its plan is named after its stem)."""

    name: str
    source: str
    units: str | None = None

    @property
    def stem(self) -> str:
        return Path(self.name).stem

    def units_or(self, default: str) -> str:
        return default if self.units is None else self.units


def parse_part(text: str) -> PartRef:
    """`door`, `part.stl` or `part.stl:in` (units mm, m or in). A colon followed by anything
    else is part of the path."""
    source, sep, units = text.rpartition(":")
    if sep and units in UNITS_TO_MM and source:
        return PartRef(source, source, units)
    return PartRef(text, text)


def parse_list_line(line: str) -> PartRef | None:
    """A list file's line: `PATH`, `PATH UNITS` or `PATH:UNITS`; None for a blank line or a
    comment (what follows a '#')."""
    entry = line.split("#", 1)[0].strip()
    if not entry:
        return None
    head, _, last = entry.rpartition(" ")
    if head.strip() and last in UNITS_TO_MM:
        return PartRef(head.strip(), head.strip(), last)
    if Path(head.strip()).suffix.lower() in MESH_SUFFIXES + STEP_SUFFIXES:
        raise ValueError(f"{entry!r}: units {last!r}: use one of {', '.join(UNITS_TO_MM)}")
    return parse_part(entry)


def read_part_list(listing: Path) -> list[PartRef]:
    """The parts a list file names, one a line (`PATH [UNITS]`), a path relative to the
    list's folder (or absolute, or a built-in part's name). A missing part is that part's
    failure, not the list's; the list must exist, name a part and no two of one stem."""
    data = read_regular(listing, "part list", MAX_PART_LIST_BYTES, "not a list of parts")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(f"part list {listing}: cannot read it ({exc})") from None
    refs = []
    for number, line in enumerate(text.splitlines(), 1):
        try:
            ref = parse_list_line(line)
        except ValueError as exc:
            raise ValueError(f"part list {listing}, line {number}: {exc}") from None
        if ref is not None:
            refs.append(_beside(ref, listing.parent))
    if not refs:
        raise ValueError(f"part list {listing} names no part (one 'PATH [UNITS]' a line)")
    _distinct(refs, f"part list {listing}")
    return refs


def _beside(ref: PartRef, base: Path) -> PartRef:
    # A name with no suffix that is no file next to the list is left to `load_part`: a
    # built-in part, or its one-line error.
    near = base / ref.source
    if near.exists() or Path(ref.source).suffix:
        return PartRef(ref.name, str(near), ref.units)
    return ref


def folder_parts(folder: Path) -> list[PartRef]:
    """The part files (meshes and STEP) directly in `folder`, sorted, each of its own stem."""
    suffixes = MESH_SUFFIXES + STEP_SUFFIXES
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in suffixes)
    if not files:
        raise ValueError(f"folder {folder} holds no part file ({', '.join(suffixes)})")
    refs = [PartRef(p.name, str(p)) for p in files]
    _distinct(refs, f"folder {folder}")
    return refs


def is_part_group(text: str) -> bool:
    """Whether a part argument names several parts (a folder or a list file), not one."""
    return Path(text).is_dir() or Path(text).suffix.lower() == PART_LIST_SUFFIX


def expand_parts(texts: list[str]) -> list[PartRef]:
    """Every part the arguments name: a part (`PATH[:UNITS]`), a folder or a list file. A
    part file named here must exist (a list's missing part is that part's failure)."""
    refs: list[PartRef] = []
    for text in texts:
        if Path(text).is_dir():
            refs += folder_parts(Path(text))
        elif Path(text).suffix.lower() == PART_LIST_SUFFIX:
            refs += read_part_list(Path(text))
        else:
            ref = parse_part(text)
            if Path(ref.source).suffix and not Path(ref.source).exists():
                raise ValueError(f"part file {ref.source} does not exist")
            refs.append(ref)
    _distinct(refs, "parts")
    return refs


def _distinct(refs: list[PartRef], where: str) -> None:
    stems = [r.stem for r in refs]
    if twice := sorted({s for s in stems if stems.count(s) > 1}):
        raise ValueError(f"{where}: parts {', '.join(twice)} would share a plan name")
