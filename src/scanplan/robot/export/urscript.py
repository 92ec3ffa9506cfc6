"""Universal Robots URScript: `movel` with blend radii through the thinned targets, metres and
rotation vectors; the acquisition switched by a standard digital output around each pass."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.robot.export.common import (
    JOINT_ACCEL_DEG_S2,
    JOINT_SPEED_DEG_S,
    ExportOptions,
    Motion,
    Parsed,
    PassTracker,
    floats,
    joint_move_targets,
    read_standoff,
    scan_output,
    sensor_poses,
    standoff_note,
)
from scanplan.robot.export.rotations import poses_from_parts

SUFFIX = ".script"
DEFAULT_SCAN_OUTPUT = "0"  # standard digital output 0
# movel(pose_trans(feature, p[...]), ...): a target in the part's feature frame.
_MOVEL = re.compile(
    r"movel\(pose_trans\(feature,\s*p\[([^\]]*)\]\),\s*a=([^,]+),\s*v=([^,]+),\s*r=([^)]+)\)"
)
_FEATURE = re.compile(r"^feature\s*=\s*p\[([^\]]*)\]")


def _poses_m(T: np.ndarray) -> list[str]:
    """`p[x, y, z, rx, ry, rz]` per pose of (n, 4, 4) mm poses."""
    values = np.concatenate(
        [T[:, :3, 3] / 1000.0, Rotation.from_matrix(T[:, :3, :3]).as_rotvec()], axis=1
    )
    # 9 decimals in metres = 1 nm: the file never limits accuracy, the controller does.
    return ["p[" + ", ".join(f"{v:.9f}" for v in row) + "]" for row in values]


def write(motion: Motion, options: ExportOptions) -> str:
    name = options.program_name
    a = options.accel_mm_s2 / 1000.0
    out_n = scan_output(options, DEFAULT_SCAN_OUTPUT, "number 0-7")
    out = [
        f"# {name}: laser-profilometer scan path written by scanplan",
        "# Targets are T_part_tcp, the TCP's pose in the part's frame, flown as",
        "# pose_trans(feature, target): `feature` is the part's pose in the base frame",
        "# (T_base_part); calibrate it (a feature plane on the pendant) and nothing else changes.",
        f"# {standoff_note(motion)}.",
        "# set_tcp below is that point: T_flange_sensor moved along the beam. Units: metres,",
        "# rotation vectors in radians, speeds m/s, accelerations m/s^2, blend radii metres.",
        f"# {len(motion.poses)} targets from {motion.n_planned} planned poses, "
        f"{int(motion.pass_start.sum())} scanning runs; scan speed {options.scan_speed:g} mm/s, "
        f"travel {options.travel_speed_mm_s:g} mm/s.",
        f"# Each run is thinned to the fewest targets within {options.chord_tol:g} mm and "
        f"{np.degrees(options.angle_tol_rad):g} deg of the plan.",
        "# Blend r = 0 at each run's start and end, so the sensor triggers on a stopped robot,",
        "# at the program's ends and before each joint move; in a run r <= "
        f"{options.blend_mm:g} mm, capped so a blend",
        "# cuts the path by at most the chord tolerance; between runs r <= "
        f"{options.move_blend_mm:g} mm, cutting a corner by at",
        f"# most {options.move_cut_mm:g} mm (a share of the {options.scan.clearance_mm:g} mm "
        "clearance the moves were planned with);",
        "# every r at most half the distance to the neighbouring targets so blends never overlap.",
        f"# Acquisition: standard digital output {out_n} is set True at each run's first target "
        "and False at its last;",
        "# wire it to the sensor's acquisition enable.",
        f"def {name}():",
        f"  set_tcp({_poses_m(options.tool[None])[0]})",
        f"  feature = {_poses_m(motion.part_pose[None])[0]}",
    ]
    joint_moves = joint_move_targets(motion, options)
    qa, qv = np.radians(JOINT_ACCEL_DEG_S2), np.radians(JOINT_SPEED_DEG_S)
    for i, target in enumerate(_poses_m(motion.poses_part)):
        k = int(motion.swath[i])
        if motion.pass_start[i]:
            out.append(f"  # pass {k} start")
        if i in joint_moves:  # into the pass's configuration
            q = ", ".join(f"{v:.6f}" for v in joint_moves[i])
            out.append(f"  movej([{q}], a={qa:.6g}, v={qv:.6g})")
        v = motion.speed_mm_s[i] / 1000.0
        r = motion.blend_mm[i] / 1000.0
        out.append(f"  movel(pose_trans(feature, {target}), a={a:.6g}, v={v:.6g}, r={r:.9g})")
        if motion.pass_start[i]:
            out.append(f'  textmsg("scanplan: pass {k} start")')
            out.append(f"  set_standard_digital_out({out_n}, True)  # acquisition on")
        if motion.pass_end[i]:
            out.append(f"  set_standard_digital_out({out_n}, False)  # acquisition off")
            out.append(f'  textmsg("scanplan: pass {k} end")')
            out.append(f"  # pass {k} end")
    out += ["end", "", f"{name}()", ""]
    return "\n".join(out)


def parse(text: str) -> Parsed:
    values: list[list[float]] = []
    feature = np.eye(4)
    tracker = PassTracker()
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("#"):
            tracker.line(s)
            continue
        if f := _FEATURE.match(s):
            x = floats(f.group(1))
            feature = poses_from_parts(np.array([x[:3]]) * 1000.0, Rotation.from_rotvec([x[3:]]))[0]
            continue
        m = _MOVEL.search(s)
        if m:
            values.append([*floats(m.group(1)), *(float(m.group(j)) for j in (2, 3, 4))])
            tracker.move()
    if not values:
        raise ValueError("URScript program holds no movel")
    arr = np.asarray(values)
    poses = feature @ poses_from_parts(arr[:, :3] * 1000.0, Rotation.from_rotvec(arr[:, 3:6]))
    poses = sensor_poses(poses, read_standoff(text))
    return Parsed(poses, np.array(tracker.flags), arr[:, 7] * 1000.0, arr[:, 8] > 0)
