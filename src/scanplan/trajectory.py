"""The Trajectory type every planner produces, and its CSV / JSON files.

Poses are sensor poses in the part frame (`T_part_sensor`, millimetres). The CSV is the
contract of SPEC §8: `swath,scanning,x_mm,y_mm,z_mm,qw,qx,qy,qz`.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

CSV_COLUMNS = ("swath", "scanning", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz")


@dataclass(frozen=True)
class Trajectory:
    """A sensor path over a part.

    poses:    (n, 4, 4) float64, `T_part_sensor` in mm.
    swath:    (n,) int, index of the pass each pose belongs to (transitions carry the index of
              the pass they lead to).
    scanning: (n,) bool, True where the sensor records profiles.
    plan_time_s: wall time the planner took.
    planner:  name of the planner that made it.
    """

    poses: np.ndarray
    swath: np.ndarray
    scanning: np.ndarray
    plan_time_s: float = 0.0
    planner: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        poses = np.asarray(self.poses, dtype=np.float64)
        if poses.ndim != 3 or poses.shape[1:] != (4, 4):
            raise ValueError(f"trajectory poses must be (n, 4, 4), got {poses.shape}")
        n = len(poses)
        swath = np.asarray(self.swath, dtype=np.int64).reshape(-1)
        scanning = np.asarray(self.scanning, dtype=bool).reshape(-1)
        if len(swath) != n or len(scanning) != n:
            raise ValueError(
                f"trajectory has {n} poses but {len(swath)} swath and {len(scanning)} flags"
            )
        if not np.isfinite(poses).all():
            raise ValueError("trajectory has non-finite poses")
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "swath", swath)
        object.__setattr__(self, "scanning", scanning)

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def positions_mm(self) -> np.ndarray:
        """(n, 3) sensor origins in the part frame."""
        return self.poses[:, :3, 3]

    @property
    def quaternions_wxyz(self) -> np.ndarray:
        """(n, 4) unit quaternions, scalar first."""
        xyzw = Rotation.from_matrix(self.poses[:, :3, :3]).as_quat()
        return np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)

    @property
    def scan_poses(self) -> np.ndarray:
        """(m, 4, 4) the poses where the sensor records."""
        return self.poses[self.scanning]

    def path_length_mm(self, scanning_only: bool = False) -> float:
        p = self.positions_mm[self.scanning] if scanning_only else self.positions_mm
        if len(p) < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())

    @staticmethod
    def concatenate(parts: list[Trajectory], planner: str = "") -> Trajectory:
        if not parts:
            raise ValueError("cannot concatenate an empty list of trajectories")
        return Trajectory(
            poses=np.concatenate([t.poses for t in parts]),
            swath=np.concatenate([t.swath for t in parts]),
            scanning=np.concatenate([t.scanning for t in parts]),
            plan_time_s=float(sum(t.plan_time_s for t in parts)),
            planner=planner or parts[0].planner,
            meta=_sum_counters([t.meta for t in parts]),
        )


def _sum_counters(metas: list[dict]) -> dict:
    """The integer counters of per-pass metadata (e.g. the rl planner's guard overrides),
    summed over the passes."""
    total: dict[str, int] = {}
    for meta in metas:
        for key, value in meta.items():
            if isinstance(value, int):
                total[key] = total.get(key, 0) + value
    return total


def poses_from_xyz_quat(xyz: np.ndarray, quat_wxyz: np.ndarray) -> np.ndarray:
    """(n, 4, 4) poses from positions and scalar-first quaternions (normalized here)."""
    q = np.asarray(quat_wxyz, dtype=np.float64)
    norms = np.linalg.norm(q, axis=1)
    if np.any(norms < 1e-9):
        raise ValueError("quaternion of zero length")
    xyzw = np.concatenate([q[:, 1:], q[:, :1]], axis=1) / norms[:, None]
    poses = np.tile(np.eye(4), (len(q), 1, 1))
    poses[:, :3, :3] = Rotation.from_quat(xyzw).as_matrix()
    poses[:, :3, 3] = xyz
    return poses


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write a file so that a failure never leaves a half-written one behind."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        # mkstemp makes the file private (0600); give it the mode a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Text version of `atomic_write_bytes` (UTF-8)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def to_csv_text(traj: Trajectory) -> str:
    q = traj.quaternions_wxyz
    p = traj.positions_mm
    lines = [",".join(CSV_COLUMNS)]
    for i in range(len(traj)):
        lines.append(
            f"{traj.swath[i]},{int(traj.scanning[i])},"
            + ",".join(f"{v:.6f}" for v in p[i])
            + ","
            + ",".join(f"{v:.9f}" for v in q[i])
        )
    return "\n".join(lines) + "\n"


def write_csv(traj: Trajectory, path: str | os.PathLike) -> None:
    atomic_write_text(path, to_csv_text(traj))


def read_csv(path: str | os.PathLike) -> Trajectory:
    """Read a trajectory CSV; every malformation raises ValueError naming the file and line."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"trajectory file {path} does not exist")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"trajectory file {path} cannot be read: {exc}") from None
    rows = [r for r in text.splitlines() if r.strip()]
    if not rows:
        raise ValueError(f"trajectory file {path} is empty")
    header = [h.strip() for h in rows[0].split(",")]
    if tuple(header) != CSV_COLUMNS:
        raise ValueError(
            f"trajectory file {path} line 1: header must be {','.join(CSV_COLUMNS)}, "
            f"got {rows[0][:80]!r}"
        )
    if len(rows) < 2:
        raise ValueError(f"trajectory file {path} has a header but no poses")
    values = np.empty((len(rows) - 1, len(CSV_COLUMNS)))
    for i, row in enumerate(rows[1:], start=2):
        cells = row.split(",")
        if len(cells) != len(CSV_COLUMNS):
            raise ValueError(
                f"trajectory file {path} line {i}: expected {len(CSV_COLUMNS)} values, "
                f"got {len(cells)}"
            )
        try:
            values[i - 2] = [float(c) for c in cells]
        except ValueError:
            raise ValueError(
                f"trajectory file {path} line {i}: not a number in {row[:80]!r}"
            ) from None
        if not np.isfinite(values[i - 2]).all():
            raise ValueError(f"trajectory file {path} line {i}: non-finite value")
        if np.linalg.norm(values[i - 2, 5:]) < 1e-9:
            raise ValueError(f"trajectory file {path} line {i}: quaternion of zero length")
    if np.any(values[:, 0] != np.round(values[:, 0])):
        raise ValueError(f"trajectory file {path}: swath column must hold integers")
    if not np.isin(values[:, 1], (0.0, 1.0)).all():
        raise ValueError(f"trajectory file {path}: scanning column must be 0 or 1")
    poses = poses_from_xyz_quat(values[:, 2:5], values[:, 5:9])
    return Trajectory(poses=poses, swath=values[:, 0].astype(int), scanning=values[:, 1] > 0.5)


def to_json_dict(traj: Trajectory) -> dict:
    return {
        "units": {"length": "mm", "rotation": "unit quaternion, scalar first (w, x, y, z)"},
        "frame": "part frame; each pose is T_part_sensor (sensor z = laser axis towards the "
        "part, x = along the laser line, y = scan direction)",
        "planner": traj.planner,
        "plan_time_s": traj.plan_time_s,
        "poses": [
            {
                "swath": int(traj.swath[i]),
                "scanning": bool(traj.scanning[i]),
                "position_mm": traj.positions_mm[i].tolist(),
                "quaternion_wxyz": traj.quaternions_wxyz[i].tolist(),
            }
            for i in range(len(traj))
        ],
    }


def write_json(traj: Trajectory, path: str | os.PathLike) -> None:
    atomic_write_text(path, json.dumps(to_json_dict(traj), indent=1))


def read_json(path: str | os.PathLike) -> Trajectory:
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        poses_in = data["poses"]
        xyz = np.array([p["position_mm"] for p in poses_in], dtype=float)
        q = np.array([p["quaternion_wxyz"] for p in poses_in], dtype=float)
        swath = [int(p["swath"]) for p in poses_in]
        scanning = [bool(p["scanning"]) for p in poses_in]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(
            f"trajectory file {path} is not a scanplan JSON trajectory: {exc}"
        ) from None
    if len(xyz) == 0:
        raise ValueError(f"trajectory file {path} has no poses")
    return Trajectory(
        poses_from_xyz_quat(xyz, q),
        np.asarray(swath),
        np.asarray(scanning),
        plan_time_s=float(data.get("plan_time_s", 0.0)),
        planner=data.get("planner", ""),
    )


def read_trajectory(path: str | os.PathLike) -> Trajectory:
    """CSV or JSON by extension."""
    if str(path).lower().endswith(".json"):
        return read_json(path)
    return read_csv(path)
