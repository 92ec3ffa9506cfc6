"""A plan's files: the trajectory as CSV (columns `swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz`,
then `e1,e2,..` where external axes hold values per pose) or JSON (a pose's `external`),
with what it was made under riding along (top-level keys of the JSON, `# key: <JSON>`
comment lines under the CSV's header, which CSV tools skip). Every malformation is a
ValueError naming the file, line and field.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from scanplan.core.files import atomic_write_text, dumps_json
from scanplan.core.limits import DURATION_S, MAX_POSES, POSITION_MM, check_count, in_range
from scanplan.core.paths import open_regular
from scanplan.core.plan_records import FILE_RECORDS, FiniteFloat, validated_records
from scanplan.core.trajectory import INT32, Trajectory, poses_from_xyz_quat
from scanplan.core.validation import field_line

CSV_COLUMNS = ("swath", "scanning", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz")
CSV_COMMENT = "#"
MAX_EXTERNAL_AXES = 6  # a controller's external axes (RAPID's eax_a..eax_f, KRL's E1..E6)


def external_columns(k: int) -> tuple[str, ...]:
    """The CSV columns of k external axes' values: e1..ek."""
    return tuple(f"e{j + 1}" for j in range(k))


def to_csv_text(traj: Trajectory) -> str:
    q = traj.quaternions_wxyz
    p = traj.positions_mm
    external = traj.external
    k = 0 if external is None else external.shape[1]
    # The records right under the header: CSV tools that know comments skip them
    # (pandas `comment="#"`, numpy `genfromtxt(names=True)`), and the header stays line 1.
    lines = [",".join((*CSV_COLUMNS, *external_columns(k)))]
    lines += [
        f"{CSV_COMMENT} {key}: {dumps_json(traj.meta[key])}"
        for key in FILE_RECORDS
        if traj.meta.get(key)
    ]
    for i in range(len(traj)):
        lines.append(
            f"{traj.swath[i]},{int(traj.scanning[i])},"
            + ",".join(f"{v:.6f}" for v in p[i])
            + ","
            + ",".join(f"{v:.9f}" for v in q[i])
            + ("".join(f",{v:.6f}" for v in external[i]) if external is not None else "")
        )
    return "\n".join(lines) + "\n"


def write_csv(traj: Trajectory, path: str | os.PathLike) -> None:
    atomic_write_text(path, to_csv_text(traj))


MAX_TRAJECTORY_FILE_BYTES = 1024**3


def _read_text(path: Path) -> str:
    """The file's text (UTF-8, a byte-order mark allowed), or ValueError naming it and, for
    a path that is not a regular file, what it is (a directory, a FIFO, a device)."""
    with open_regular(path, "trajectory file") as f:
        size = os.fstat(f.fileno()).st_size
        if size > MAX_TRAJECTORY_FILE_BYTES:
            raise ValueError(
                f"trajectory file {path} is {size / 1024**3:.1f} GiB: more than "
                f"{MAX_TRAJECTORY_FILE_BYTES / 1024**3:.0f} GiB, not a trajectory"
            )
        try:
            data = f.read(MAX_TRAJECTORY_FILE_BYTES)
        except OSError as exc:
            raise ValueError(
                f"trajectory file {path} cannot be read: {exc.strerror or exc}"
            ) from None
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"trajectory file {path} is not UTF-8 text (byte {exc.start})") from None


def read_csv(path: str | os.PathLike, text: str | None = None) -> Trajectory:
    """Read a trajectory CSV (`text`: its contents, already read); every malformation raises
    ValueError naming the file, line and column."""
    path = Path(path)
    text = _read_text(path) if text is None else text
    lines = text.splitlines()
    numbers = [i for i, r in enumerate(lines, start=1) if r.strip()]
    meta = _csv_records(path, lines, numbers)
    numbers = [i for i in numbers if not lines[i - 1].lstrip().startswith(CSV_COMMENT)]
    if not numbers:
        raise ValueError(f"trajectory file {path} is empty")
    first = numbers[0]
    header = [h.strip() for h in lines[first - 1].split(",")]
    if tuple(header[: len(CSV_COLUMNS)]) == CSV_COLUMNS and "speed_mm_s" in header:
        raise ValueError(
            f"trajectory file {path} is a robot program exported as CSV (targets in the robot's "
            "base frame, with speeds and blends), not a plan: give the plan it was exported from"
        )
    k = _external_count(header)
    columns = (*CSV_COLUMNS, *external_columns(k))
    if tuple(header) != columns:
        missing = [c for c in CSV_COLUMNS if c not in header]
        extra = [c for c in header if c not in CSV_COLUMNS]
        detail = (f"missing {', '.join(missing)}; " if missing else "") + (
            f"unknown {', '.join(repr(c[:20]) for c in extra)}; " if extra else ""
        )
        raise ValueError(
            f"trajectory file {path} line {first}: header must be {','.join(CSV_COLUMNS)} "
            f"({detail or 'wrong order; '}got {lines[first - 1][:60]!r})"
        )
    numbers = numbers[1:]
    if not numbers:
        raise ValueError(f"trajectory file {path} has a header but no poses")
    check_count(len(numbers), MAX_POSES, f"trajectory file {path}: poses")
    cells = [lines[i - 1].split(",") for i in numbers]
    counts = np.array([len(c) for c in cells])
    wrong = np.flatnonzero(counts != len(columns))
    if len(wrong):
        raise ValueError(
            f"trajectory file {path} line {numbers[wrong[0]]}: expected {len(columns)} "
            f"values, got {counts[wrong[0]]}"
        )
    try:
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        values = _locate_bad_number(path, cells, numbers, columns)
    line = np.asarray(numbers)
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise ValueError(
            f"trajectory file {path} line {line[row]}, column {columns[col]}: non-finite value"
        )
    far = ~((values[:, 2:5] >= POSITION_MM.lo) & (values[:, 2:5] <= POSITION_MM.hi))
    if far.any():
        row, col = np.argwhere(far)[0]
        POSITION_MM.check(
            values[row, 2 + col],
            f"trajectory file {path} line {line[row]}, column {CSV_COLUMNS[2 + col]}:",
        )
    swath = values[:, 0]
    bad_swath = (swath != np.round(swath)) | (np.abs(swath) > INT32.max)
    if bad_swath.any():
        row = np.flatnonzero(bad_swath)[0]
        raise ValueError(
            f"trajectory file {path} line {line[row]}, column swath: must be an integer "
            f"that fits 32 bits, got {swath[row]:g}"
        )
    bad_flag = ~np.isin(values[:, 1], (0.0, 1.0))
    if bad_flag.any():
        row = np.flatnonzero(bad_flag)[0]
        raise ValueError(
            f"trajectory file {path} line {line[row]}: scanning column must be 0 or 1, "
            f"got {cells[row][1].strip()[:20]!r}"
        )
    zero_q = np.linalg.norm(values[:, 5:], axis=1) < 1e-9
    if zero_q.any():
        raise ValueError(
            f"trajectory file {path} line {line[np.flatnonzero(zero_q)[0]]}: "
            "quaternion of zero length"
        )
    poses = poses_from_xyz_quat(values[:, 2:5], values[:, 5:9])
    planner = str(meta.get("context", {}).get("planner", "")) if meta.get("context") else ""
    return Trajectory(
        poses=poses,
        swath=swath.astype(np.int64),
        scanning=values[:, 1] > 0.5,
        planner=planner,
        meta=meta,
        external=values[:, len(CSV_COLUMNS) :] if k else None,
    )


def _external_count(header: list[str]) -> int:
    """How many external axes' columns (e1..ek) follow the pose columns of `header`."""
    extra = header[len(CSV_COLUMNS) :]
    k = min(len(extra), MAX_EXTERNAL_AXES)
    return k if tuple(extra[:k]) == external_columns(k) else 0


def _csv_records(path: Path, lines: list[str], numbers: list[int]) -> dict[str, Any]:
    """The `# key: <JSON>` comment lines (FILE_RECORDS; other comments are free)."""
    meta: dict[str, Any] = {}
    for i in numbers:
        line = lines[i - 1].lstrip()
        if not line.startswith(CSV_COMMENT):
            continue
        key, sep, value = line[len(CSV_COMMENT) :].partition(":")
        if not sep or key.strip() not in FILE_RECORDS:
            continue
        try:
            meta[key.strip()] = json.loads(value)
        except (ValueError, RecursionError):
            raise ValueError(
                f"trajectory file {path} line {i}: the {key.strip()} record is not valid JSON"
            ) from None
    return validated_records(meta, f"trajectory file {path}")


def _locate_bad_number(
    path: Path, cells: list[list[str]], numbers: list[int], columns: tuple[str, ...]
) -> np.ndarray:
    """Only on the error path: find the first cell that is not a number, to name it."""
    for row, line in zip(cells, numbers, strict=True):
        for col, cell in enumerate(row):
            try:
                float(cell)
            except ValueError:
                raise ValueError(
                    f"trajectory file {path} line {line}, column {columns[col]}: "
                    f"not a number: {cell.strip()[:20]!r}"
                ) from None
    raise AssertionError("unreachable: numpy refused a table float() accepts")


def to_json_dict(traj: Trajectory) -> dict:
    positions, quaternions = traj.positions_mm.tolist(), traj.quaternions_wxyz.tolist()
    external = None if traj.external is None else traj.external.tolist()
    return {
        "units": {"length": "mm", "rotation": "unit quaternion, scalar first (w, x, y, z)"},
        "frame": "part frame; each pose is T_part_sensor (sensor z = laser axis towards the "
        "part, x = along the laser line, y = scan direction)",
        "planner": traj.planner,
        "plan_time_s": traj.plan_time_s,
        **{key: traj.meta[key] for key in FILE_RECORDS if traj.meta.get(key)},
        "poses": [
            {
                "swath": int(traj.swath[i]),
                "scanning": bool(traj.scanning[i]),
                "position_mm": positions[i],
                "quaternion_wxyz": quaternions[i],
                **({} if external is None else {"external": external[i]}),
            }
            for i in range(len(traj))
        ],
    }


def write_json(traj: Trajectory, path: str | os.PathLike) -> None:
    atomic_write_text(path, dumps_json(to_json_dict(traj), indent=1))


def as_read(traj: Trajectory, path: str | os.PathLike) -> Trajectory:
    """`traj` as a command will read it back from the file `path` (its poses rounded as the
    CSV or JSON holds them), without touching the disk: what `plan` times its program on, so
    that it prints the figure `export` and `evaluate` print."""
    if str(path).lower().endswith(".json"):
        return read_json(path, dumps_json(to_json_dict(traj)))
    return read_csv(path, to_csv_text(traj))


class _PoseJson(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    swath: int = Field(ge=int(INT32.min), le=int(INT32.max))
    scanning: bool
    position_mm: list[Annotated[float, in_range(POSITION_MM)]] = Field(min_length=3, max_length=3)
    quaternion_wxyz: list[FiniteFloat] = Field(min_length=4, max_length=4)
    external: list[FiniteFloat] | None = Field(None, min_length=1, max_length=MAX_EXTERNAL_AXES)


class _TrajectoryJson(BaseModel):
    # Strict: a planner of 3 or a plan time of "fast" is a broken file, not a value to coerce.
    model_config = ConfigDict(extra="ignore", strict=True)
    planner: str = ""
    plan_time_s: Annotated[float, in_range(DURATION_S)] = 0.0
    poses: list[_PoseJson] = Field(min_length=1)


def read_json(path: str | os.PathLike, text: str | None = None) -> Trajectory:
    """Read a trajectory JSON (as `write_json` writes it; `text`: its contents, already
    read); ValueError naming file and field."""
    path = Path(path)
    text = _read_text(path) if text is None else text
    try:
        data = json.loads(text)
    except RecursionError:
        raise ValueError(f"trajectory file {path}: JSON nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, and ints too long to convert
        raise ValueError(f"trajectory file {path} is not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"trajectory file {path}: expected a JSON object with 'poses'")
    if isinstance(data.get("poses"), list):  # counted before each is validated
        check_count(len(data["poses"]), MAX_POSES, f"trajectory file {path}: poses")
    meta = validated_records(data, f"trajectory file {path}")
    try:
        model = _TrajectoryJson.model_validate(data)
    except ValidationError as exc:
        raise ValueError(f"trajectory file {path}: {field_line(exc)}") from None
    xyz = np.array([p.position_mm for p in model.poses], dtype=np.float64)
    q = np.array([p.quaternion_wxyz for p in model.poses], dtype=np.float64)
    zero_q = np.linalg.norm(q, axis=1) < 1e-9
    if zero_q.any():
        raise ValueError(
            f"trajectory file {path}: poses[{np.flatnonzero(zero_q)[0]}].quaternion_wxyz: "
            "quaternion of zero length"
        )
    return Trajectory(
        poses_from_xyz_quat(xyz, q),
        np.array([p.swath for p in model.poses], dtype=np.int64),
        np.array([p.scanning for p in model.poses], dtype=bool),
        plan_time_s=model.plan_time_s,
        planner=model.planner,
        meta=meta,
        external=_json_external(path, model.poses),
    )


def _json_external(path: Path, poses: list[_PoseJson]) -> np.ndarray | None:
    """(n, k) the poses' external axis values: every pose has k, or none has any."""
    counts = {len(p.external) if p.external is not None else 0 for p in poses}
    if counts == {0}:
        return None
    if len(counts) > 1:
        first = next(
            i for i, p in enumerate(poses) if len(p.external or ()) != len(poses[0].external or ())
        )
        raise ValueError(
            f"trajectory file {path}: poses[{first}].external: every pose holds as many "
            "external axis values as the first"
        )
    return np.array([p.external for p in poses], dtype=np.float64)


def read_trajectory(path: str | os.PathLike) -> Trajectory:
    """CSV or JSON by extension."""
    if str(path).lower().endswith(".json"):
        return read_json(path)
    return read_csv(path)
