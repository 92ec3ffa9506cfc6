"""ABB RAPID module: robtargets (mm, quaternion scalar first, the confdata the reach check
chose), sensor tooldata, the part as work object, MoveL with zones, SetDO around each pass."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.robot.export.axes_lines import axes_note, mount_note, on_axes, read_axes
from scanplan.robot.export.common import (
    ExportOptions,
    Kinematics,
    Motion,
    Parsed,
    PassTracker,
    floats,
    read_standoff,
    scan_output,
    sensor_poses,
    standoff_note,
)
from scanplan.robot.export.joint_moves import joint_move_targets, target_joints
from scanplan.robot.export.rotations import poses_from_parts, quat_wxyz

SUFFIX = ".mod"
DEFAULT_SCAN_OUTPUT = "doScan"
_EXTAX = "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]"
_TARGET = re.compile(r"CONST\s+robtarget\s+(\w+)\s*:=\s*\[\[([^\]]*)\],\s*\[([^\]]*)\]")
_SPEED = re.compile(r"CONST\s+speeddata\s+(\w+)\s*:=\s*\[([^,\]]+)")
# The work object's user frame: wobjdata [robhold, ufprog, ufmec, uframe, oframe].
_WOBJ = re.compile(r"wobjdata\s+\w+\s*:=\s*\[\w+,\w+,\"[^\"]*\",\[\[([^\]]*)\],\[([^\]]*)\]\]")
_MOVEL = re.compile(r"MoveL\s+(\w+)\s*,\s*(\w+)\s*,\s*(\w+)\s*,")
# A robtarget's extax: [eax_a, ..., eax_f] after its confdata.
_TARGET_EXTAX = re.compile(
    r"CONST\s+robtarget\s+(\w+)\s*:=\s*\[\[[^\]]*\],\s*\[[^\]]*\],\s*\[[^\]]*\],\s*\[([^\]]*)\]"
)
_UNUSED = 9e9  # an external axis a robtarget does not use


def _extax(motion: Motion) -> list[str]:
    """`[eax_a,...,eax_f]` per target: the external axes' values (degrees, mm), 9E+09
    where unused."""
    if motion.external is None:
        return [_EXTAX] * len(motion.poses)
    k = motion.external.shape[1]
    return [
        "[" + ",".join([*(f"{v:.6f}" for v in row), *(["9E+09"] * (6 - k))]) + "]"
        for row in motion.external
    ]


def _frames(T: np.ndarray) -> list[str]:
    """`[x,y,z],[q1,q2,q3,q4]` per pose of (n, 4, 4) mm poses."""
    q = quat_wxyz(T[:, :3, :3])
    return [
        "[" + ",".join(f"{v:.6f}" for v in p) + "],[" + ",".join(f"{v:.9f}" for v in r) + "]"
        for p, r in zip(T[:, :3, 3], q, strict=True)
    ]


def confdata(q_rad: np.ndarray, arm: Kinematics | None) -> np.ndarray:
    """(n, 4) int ABB confdata [cf1, cf4, cf6, cfx] of (n, 6) joint angles (rad, the
    controller's): cf1/cf4/cf6 the quadrant of axes 1, 4, 6 (0 for [0°, 90°), -1 for
    [-90°, 0)...); cfx = 4·(wrist centre behind axis 1) + 2·(wrist centre behind the lower
    arm) + (axis 5 < 0), 0 without an arm to say it."""
    q = np.asarray(q_rad, dtype=np.float64)
    quadrants = np.floor(np.degrees(q[:, [0, 3, 5]]) / 90.0).astype(int)
    if arm is None:
        cfx = np.zeros(len(q), dtype=int)
    else:
        terms = arm.singularity_terms(q)
        cfx = 4 * (terms[:, 2] < 0) + 2 * (terms[:, 1] < 0) + (q[:, 4] < 0)
    return np.column_stack([quadrants, cfx]).astype(int)


def _zone_name(blend_mm: float) -> str:
    """zScan<hundredths of a mm>, the radius rounded down so the cap still holds."""
    return f"zScan{int(np.floor(blend_mm * 100.0 + 1e-9))}"


def write(motion: Motion, options: ExportOptions) -> str:
    n = len(motion.poses)
    width = len(str(n - 1))
    signal = scan_output(options, DEFAULT_SCAN_OUTPUT, "name")
    joints = target_joints(motion, options)
    if joints is None or not np.isfinite(joints).all():
        conf = np.zeros((n, 4), dtype=int)
        if joints is not None:
            ok = np.isfinite(joints).all(axis=1)
            conf[ok] = confdata(joints[ok], options.arm)
    else:
        conf = confdata(joints, options.arm)
    zones = {
        _zone_name(b): float(np.floor(b * 100.0 + 1e-9) / 100.0)
        for b in motion.blend_mm
        if np.floor(b * 100.0 + 1e-9) > 0
    }
    extax = _extax(motion)
    axes_lines = []
    if motion.axes is not None:
        which = ", ".join(f"eax_{'abcdef'[j]} {n}" for j, n in enumerate(motion.axes.labels))
        axes_lines = [
            f"  ! External axes in every robtarget's extax: {which}. wobjPart is",
            "  ! the part with every axis at 0: with a turntable, make it a coordinated work",
            "  ! object moved by the turntable's mechanical unit (ufmec), so it turns with",
            "  ! eax_a; with a track, the robot's base rides it (a track unit).",
            *(
                [f"  ! {mount_note(motion)} (gravity beta 180 deg, the base frame the world)."]
                if motion.axes.overhead
                else []
            ),
            f"  ! {axes_note(motion)}",
        ]
    out = [
        f"MODULE {options.program_name}",
        "  ! Laser-profilometer scan path written by scanplan.",
        "  ! Targets are T_part_tcp, the TCP's pose in the part's frame, in the work object",
        "  ! wobjPart (its user frame is T_base_part: calibrate it and nothing else changes),",
        "  ! for tool tSensor (T_flange_sensor moved along the beam to the TCP).",
        f"  ! {standoff_note(motion)}.",
        "  ! mm, quaternions",
        "  ! [q1..q4] scalar first. Each target's confdata [cf1,cf4,cf6,cfx] is the",
        "  ! configuration the reach check chose ([0,0,0,0] when no arm was checked); every",
        "  ! run is entered by MoveAbsJ into that configuration and ConfL\\Off lets the linear",
        "  ! moves keep it.",
        "  ! tSensor's load [1 kg at 0,0,50 mm] is a placeholder: enter the real sensor load.",
        f"  ! {n} targets from {motion.n_planned} planned poses, "
        f"{int(motion.pass_start.sum())} scanning runs; each run thinned to the fewest",
        f"  ! targets within {options.chord_tol:g} mm and {np.degrees(options.angle_tol_rad):g} "
        "deg of the plan; zones zScan<r in 0.01 mm> cut",
        "  ! the path by at most that chord tolerance in a run and by at most "
        f"{options.move_cut_mm:g} mm between runs",
        f"  ! (a share of the {options.scan.clearance_mm:g} mm clearance the moves were planned "
        "with); fine at each run's start and end,",
        "  ! at the program's ends and before each MoveAbsJ.",
        f"  ! Acquisition: SetDO {signal}, 1 at each run's first target, 0 at its last (after a",
        "  ! fine point, so it switches with the robot standing there): define the signal in",
        "  ! the I/O configuration and wire it to the sensor's acquisition enable.",
        *axes_lines,
        f"  PERS tooldata tSensor := [TRUE,[{_frames(options.tool[None])[0]}],"
        "[1,[0,0,50],[1,0,0,0],0,0,0]];",
        f'  PERS wobjdata wobjPart := [FALSE,TRUE,"",[{_frames(motion.part_pose[None])[0]}],'
        "[[0,0,0],[1,0,0,0]]];",
        f"  CONST speeddata vScan := [{options.scan_speed:.3f},500,5000,1000];",
        f"  CONST speeddata vTravel := [{options.travel_speed_mm_s:.3f},500,5000,1000];",
    ]
    for zname, r in sorted(zones.items(), key=lambda item: item[1]):
        # Same proportions as the predefined zones (z5 = [FALSE,5,8,8,0.8,8,0.8]).
        b, z, o = f"{r:.3f}", f"{1.5 * r:.3f}", f"{0.15 * r:.4f}"
        out.append(f"  CONST zonedata {zname} := [FALSE,{b},{z},{z},{o},{z},{o}];")
    for i, frame in enumerate(_frames(motion.poses_part)):
        cf = ",".join(str(int(c)) for c in conf[i])
        out.append(f"  CONST robtarget p{i:0{width}d} := [{frame},[{cf}],{extax[i]}];")
    out += ["", "  PROC main()", "    ConfL\\Off;"]
    joint_moves = joint_move_targets(motion, options)
    for i in range(n):
        k = int(motion.swath[i])
        if motion.pass_start[i]:
            out.append(f"    ! pass {k} start")
        if i in joint_moves:  # into the pass's configuration (axis angles, degrees)
            q = ",".join(f"{v:.4f}" for v in np.degrees(joint_moves[i]))
            out.append(f"    MoveAbsJ [[{q}],{extax[i]}], vTravel, fine, tSensor\\WObj:=wobjPart;")
        speed = "vScan" if motion.scanning[i] and not motion.pass_start[i] else "vTravel"
        zname = _zone_name(motion.blend_mm[i])
        z_i = zname if zname in zones else "fine"
        out.append(f"    MoveL p{i:0{width}d}, {speed}, {z_i}, tSensor\\WObj:=wobjPart;")
        if motion.pass_start[i]:
            out.append(f"    SetDO {signal}, 1;  ! acquisition on")
        if motion.pass_end[i]:
            out.append(f"    SetDO {signal}, 0;  ! acquisition off")
            out.append(f"    ! pass {k} end")
    out += ["    ConfL\\On;", "  ENDPROC", "ENDMODULE", ""]
    return "\n".join(out)


def parse(text: str) -> Parsed:
    targets: dict[str, tuple[list[float], list[float]]] = {}
    extaxes: dict[str, list[float]] = {}
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
            if e := _TARGET_EXTAX.search(s):
                extaxes[m.group(1)] = [float(v) for v in e.group(2).split(",")]
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
    axes = read_axes(text)
    values = None
    if axes is not None:
        k = len(axes.names)
        values = np.array([extaxes.get(t, [_UNUSED] * 6)[:k] for t in names], dtype=np.float64)
        if (np.abs(values) >= _UNUSED * 0.99).any():
            raise ValueError("RAPID robtarget without its external axis values (extax)")
    return Parsed(
        sensor_poses(
            on_axes(uframe, poses_from_parts(xyz, rot), values, axes), read_standoff(text)
        ),
        np.array(tracker.flags),
        speed,
        np.array([b for _, b in moves]),
        values,
    )
