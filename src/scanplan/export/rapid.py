"""ABB RAPID module: robtargets (mm, quaternion scalar first), sensor tooldata, MoveL."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.export.common import (
    ExportOptions,
    Motion,
    Parsed,
    PassTracker,
    floats,
    joint_move_targets,
    poses_from_parts,
    quat_wxyz,
)

SUFFIX = ".mod"
_EXTAX = "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]"
_TARGET = re.compile(r"CONST\s+robtarget\s+(\w+)\s*:=\s*\[\[([^\]]*)\],\s*\[([^\]]*)\]")
_SPEED = re.compile(r"CONST\s+speeddata\s+(\w+)\s*:=\s*\[([^,\]]+)")
# The work object's user frame: wobjdata [robhold, ufprog, ufmec, uframe, oframe].
_WOBJ = re.compile(r"wobjdata\s+\w+\s*:=\s*\[\w+,\w+,\"[^\"]*\",\[\[([^\]]*)\],\[([^\]]*)\]\]")
_MOVEL = re.compile(r"MoveL\s+(\w+)\s*,\s*(\w+)\s*,\s*(\w+)\s*,")


def _frames(T: np.ndarray) -> list[str]:
    """`[x,y,z],[q1,q2,q3,q4]` per pose of (n, 4, 4) mm poses."""
    q = quat_wxyz(T[:, :3, :3])
    return [
        "[" + ",".join(f"{v:.6f}" for v in p) + "],[" + ",".join(f"{v:.9f}" for v in r) + "]"
        for p, r in zip(T[:, :3, 3], q, strict=True)
    ]


def write(motion: Motion, options: ExportOptions) -> str:
    n = len(motion.poses)
    width = len(str(n - 1))
    blend = options.blend_mm
    zone = "zScan" if blend > 0 else "fine"
    out = [
        f"MODULE {options.program_name}",
        "  ! Laser-profilometer scan path written by scanplan.",
        "  ! Targets are T_part_sensor, the sensor pose in the part's frame, in the work object",
        "  ! wobjPart (its user frame is T_base_part: calibrate it and nothing else changes),",
        "  ! for tool tSensor (T_flange_sensor). mm, quaternions",
        "  ! [q1..q4] scalar first. Targets carry confdata [0,0,0,0]: ConfL\\Off lets the",
        "  ! controller choose the configuration nearest the current one.",
        "  ! tSensor's load [1 kg at 0,0,50 mm] is a placeholder: enter the real sensor load.",
        f"  ! {n} targets, {int(motion.pass_start.sum())} scanning runs; fine at every run "
        "start/end and transition.",
        f"  PERS tooldata tSensor := [TRUE,[{_frames(options.tcp[None])[0]}],"
        "[1,[0,0,50],[1,0,0,0],0,0,0]];",
        f'  PERS wobjdata wobjPart := [FALSE,TRUE,"",[{_frames(motion.part_pose[None])[0]}],'
        "[[0,0,0],[1,0,0,0]]];",
        f"  CONST speeddata vScan := [{options.scan_speed:.3f},500,5000,1000];",
        f"  CONST speeddata vTravel := [{options.travel_speed_mm_s:.3f},500,5000,1000];",
    ]
    if blend > 0:
        # Same proportions as the predefined zones (z5 = [FALSE,5,8,8,0.8,8,0.8]).
        b = f"{blend:.3f}"
        z = f"{1.5 * blend:.3f}"
        o = f"{0.15 * blend:.4f}"
        out.append(f"  CONST zonedata zScan := [FALSE,{b},{z},{z},{o},{z},{o}];")
    for i, frame in enumerate(_frames(motion.poses_part)):
        out.append(f"  CONST robtarget p{i:0{width}d} := [{frame},[0,0,0,0],{_EXTAX}];")
    out += ["", "  PROC main()", "    ConfL\\Off;"]
    joint_moves = joint_move_targets(motion, options)
    for i in range(n):
        k = int(motion.swath[i])
        if motion.pass_start[i]:
            out.append(f"    ! pass {k} start")
        if i in joint_moves:  # into the pass's configuration (axis angles, degrees)
            q = ",".join(f"{v:.4f}" for v in np.degrees(joint_moves[i]))
            out.append(f"    MoveAbsJ [[{q}],{_EXTAX}], vTravel, fine, tSensor\\WObj:=wobjPart;")
        speed = "vScan" if motion.scanning[i] and not motion.pass_start[i] else "vTravel"
        z_i = zone if motion.blend_mm[i] > 0 else "fine"
        out.append(f"    MoveL p{i:0{width}d}, {speed}, {z_i}, tSensor\\WObj:=wobjPart;")
        if motion.pass_start[i]:
            out.append("    ! SetDO doSensorTrigger, 1;  ! hook: start the sensor's acquisition")
        if motion.pass_end[i]:
            out.append("    ! SetDO doSensorTrigger, 0;  ! hook: stop the sensor's acquisition")
            out.append(f"    ! pass {k} end")
    out += ["    ConfL\\On;", "  ENDPROC", "ENDMODULE", ""]
    return "\n".join(out)


def parse(text: str) -> Parsed:
    targets: dict[str, tuple[list[float], list[float]]] = {}
    speeds: dict[str, float] = {}
    names: list[str] = []
    moves: list[tuple[str, bool]] = []
    uframe = np.eye(4)
    tracker = PassTracker()
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("!"):
            tracker.line(s)
        elif m := _WOBJ.search(s):
            origin, q = floats(m.group(1)), floats(m.group(2))
            turn = Rotation.from_quat([[*q[1:], q[0]]])
            uframe = poses_from_parts(np.array([origin]), turn)[0]
        elif m := _TARGET.search(s):
            targets[m.group(1)] = (floats(m.group(2)), floats(m.group(3)))
        elif m := _SPEED.search(s):
            speeds[m.group(1)] = float(m.group(2))
        elif m := _MOVEL.search(s):
            names.append(m.group(1))
            moves.append((m.group(2), m.group(3) != "fine"))
            tracker.move()
    if not names:
        raise ValueError("RAPID module holds no MoveL")
    missing = sorted(set(names) - set(targets))
    if missing:
        raise ValueError(f"RAPID MoveL to undefined robtarget(s) {missing[:3]}")
    xyz = np.array([targets[t][0] for t in names])
    wxyz = np.array([targets[t][1] for t in names])
    rot = Rotation.from_quat(np.concatenate([wxyz[:, 1:], wxyz[:, :1]], axis=1))
    speed = np.array([speeds[v] for v, _ in moves])
    return Parsed(
        uframe @ poses_from_parts(xyz, rot),
        np.array(tracker.flags),
        speed,
        np.array([b for _, b in moves]),
    )
