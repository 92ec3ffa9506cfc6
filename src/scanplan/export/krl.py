"""KUKA KRL .src: LIN motions with {X,Y,Z,A,B,C} (mm, intrinsic ZYX Euler in degrees)."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.export.common import (
    ExportOptions,
    Motion,
    Parsed,
    PassTracker,
    euler_zyx_deg,
    joint_move_targets,
    pose_from_xyzabc,
)

SUFFIX = ".src"
_AXES = ("X", "Y", "Z", "A", "B", "C")
_LIN = re.compile(r"^LIN\s*\{([^}]*)\}\s*(C_DIS)?", re.IGNORECASE)
_BASE = re.compile(r"^\$BASE\s*=\s*\{([^}]*)\}", re.IGNORECASE)
_VEL = re.compile(r"^\$VEL\.CP\s*=\s*([-+0-9.eE]+)", re.IGNORECASE)


def _frames(T: np.ndarray) -> list[str]:
    """`{X x,Y y,Z z,A a,B b,C c}` per pose of (n, 4, 4) mm poses."""
    values = np.concatenate([T[:, :3, 3], euler_zyx_deg(T[:, :3, :3])], axis=1)
    return [
        "{" + ",".join(f"{k} {v:.6f}" for k, v in zip(_AXES, row, strict=True)) + "}"
        for row in values
    ]


def write(motion: Motion, options: ExportOptions) -> str:
    name = options.program_name
    out = [
        "&ACCESS RVP",
        "&REL 1",
        f"DEF {name}( )",
        "; Laser-profilometer scan path written by scanplan. Save as "
        f"{name}.src (KRL wants the file named after the DEF).",
        "; Targets are T_part_sensor, the sensor pose in the part's frame: $BASE is the part",
        "; (T_base_part; assumes $WORLD = $ROBROOT; calibrate it as a BASE_DATA and nothing",
        "; else changes) and $TOOL is the sensor (T_flange_sensor).",
        "; X,Y,Z in mm; A,B,C in degrees, A about Z, B about Y',"
        "; C about X''. $VEL.CP in m/s, $APO.CDIS in mm.",
        f"; {len(motion.poses)} targets, {int(motion.pass_start.sum())} scanning runs; "
        "no C_DIS (exact stop) at run starts/ends and transitions.",
        "  BAS(#INITMOV, 0)",
        f"  $BASE = {_frames(motion.part_pose[None])[0]}",
        f"  $TOOL = {_frames(options.tcp[None])[0]}",
        "  $ADVANCE = 3",
        f"  $ACC.CP = {options.accel_mm_s2 / 1000.0:.6g}",
        f"  $APO.CDIS = {options.blend_mm:.6g}",
    ]
    speed = None
    joint_moves = joint_move_targets(motion, options)
    for i, frame in enumerate(_frames(motion.poses_part)):
        k = int(motion.swath[i])
        if motion.pass_start[i]:
            out.append(f"  ; pass {k} start")
        if i in joint_moves:  # into the pass's configuration (axis angles, degrees)
            axes = ",".join(f"A{j + 1} {v:.4f}" for j, v in enumerate(np.degrees(joint_moves[i])))
            out.append(f"  PTP {{{axes}}}")
        if motion.speed_mm_s[i] != speed:
            speed = motion.speed_mm_s[i]
            out.append(f"  $VEL.CP = {speed / 1000.0:.6g}")
        out.append(f"  LIN {frame}" + (" C_DIS" if motion.blend_mm[i] > 0 else ""))
        if motion.pass_start[i]:
            out.append("  ; $OUT[1] = TRUE  ; hook: start the sensor's acquisition")
        if motion.pass_end[i]:
            out.append("  ; $OUT[1] = FALSE  ; hook: stop the sensor's acquisition")
            out.append(f"  ; pass {k} end")
    out += ["END", ""]
    return "\n".join(out)


def parse(text: str) -> Parsed:
    rows: list[list[float]] = []
    speeds: list[float] = []
    blended: list[bool] = []
    tracker = PassTracker()
    speed = float("nan")
    base = np.eye(4)
    for line in text.splitlines():
        s = line.strip()
        if s.startswith(";"):
            tracker.line(s)
        elif m := _BASE.match(s):
            items = dict(item.split() for item in m.group(1).split(","))
            base = pose_from_xyzabc(float(items[k]) for k in _AXES)
        elif m := _VEL.match(s):
            speed = float(m.group(1)) * 1000.0
        elif m := _LIN.match(s):
            items = dict(item.split() for item in m.group(1).split(","))
            rows.append([float(items[k]) for k in _AXES])
            speeds.append(speed)
            blended.append(m.group(2) is not None)
            tracker.move()
    if not rows:
        raise ValueError("KRL program holds no LIN")
    arr = np.asarray(rows)
    poses = np.tile(np.eye(4), (len(arr), 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("ZYX", arr[:, 3:], degrees=True).as_matrix()
    poses[:, :3, 3] = arr[:, :3]
    return Parsed(base @ poses, np.array(tracker.flags), np.array(speeds), np.array(blended))
