"""KUKA KRL .src: LIN motions with {X,Y,Z,A,B,C} (mm, intrinsic ZYX Euler in degrees), each
pass entered by a PTP to an E6POS with the Status and Turn of the configuration chosen."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.robot.base import euler_zyx_deg
from scanplan.robot.export.axes_lines import (
    HUNG_WORLD_BASE,
    axes_note,
    mount_note,
    on_axes,
    read_axes,
    world_base,
)
from scanplan.robot.export.common import (
    ExportOptions,
    Kinematics,
    Motion,
    Parsed,
    PassTracker,
    read_standoff,
    scan_output,
    sensor_poses,
    standoff_note,
)
from scanplan.robot.export.joint_moves import joint_move_targets
from scanplan.robot.export.rotations import pose_from_xyzabc

SUFFIX = ".src"
DEFAULT_SCAN_OUTPUT = "1"  # $OUT[1]
_AXES = ("X", "Y", "Z", "A", "B", "C")
# LIN {X ...} and PTP {X ..., S ..., T ...}: Cartesian targets (a PTP {A1 ...} is not one).
_MOVE = re.compile(r"^(LIN|PTP)\s*\{(\s*X[^}]*)\}\s*(C_DIS|C_PTP)?", re.IGNORECASE)
_BASE = re.compile(r"^\$BASE\s*=\s*\{([^}]*)\}", re.IGNORECASE)
_VEL = re.compile(r"^\$VEL\.CP\s*=\s*([-+0-9.eE]+)", re.IGNORECASE)


def _frames(T: np.ndarray) -> list[str]:
    """`{X x,Y y,Z z,A a,B b,C c}` per pose of (n, 4, 4) mm poses."""
    values = np.concatenate([T[:, :3, 3], euler_zyx_deg(T[:, :3, :3])], axis=1)
    return [
        "{" + ",".join(f"{k} {v:.6f}" for k, v in zip(_AXES, row, strict=True)) + "}"
        for row in values
    ]


def status_turn(q_rad: np.ndarray, arm: Kinematics) -> tuple[int, int]:
    """KUKA (Status, Turn) of the joint angles `q_rad` (6,), the controller's own.

    Status bit 0: the wrist root point lies behind axis 1 (x < 0 in the frame turning with
    A1: overhead area); bit 1: A3 ≥ φ, the wrist root point in front of the line through A2
    and A3 (φ: A3 with the arm stretched, set by the A3–A4 offset); bit 2: A5 < 0.
    Turn bit i: axis i+1 < 0.
    """
    q = np.asarray(q_rad, dtype=np.float64)
    wrist, elbow, shoulder = arm.singularity_terms(q)
    a5 = np.degrees(q[4])
    status = int(shoulder < 0) | int(elbow >= 0) << 1 | int(-180.0 <= a5 < 0.0 or a5 >= 180.0) << 2
    turn = sum(1 << i for i, v in enumerate(q) if v < 0)
    return status, turn


def _external(motion: Motion) -> list[str]:
    """`,E1 v,E2 w` per target: the external axes' values (degrees, mm); '' without axes."""
    if motion.external is None:
        return [""] * len(motion.poses)
    return ["".join(f",E{j + 1} {v:.6f}" for j, v in enumerate(row)) for row in motion.external]


def _axes_header(motion: Motion) -> list[str]:
    """What the header says of the external axes: which E is which, and the axes' record."""
    if motion.axes is None:
        return []
    names = ", ".join(f"E{j + 1} {n}" for j, n in enumerate(motion.axes.labels))
    out = [
        f"; External axes on every target: {names}, moved with the arm.",
        "; $BASE is the part with every external axis at 0. A turntable: declare that base",
        "; as coupled to the turntable's kinematics (BASE_TYPE #EK on its flange), so the",
        "; controller turns it with E1. A track: $ROBROOT rides it (a ROBROOT kinematic),",
        "; its travel along the track direction below.",
    ]
    if motion.axes.overhead:
        out += [
            f"; {mount_note(motion)}: $ROBROOT = {_frames(HUNG_WORLD_BASE[None])[0]}",
            "; in $WORLD (set in the machine data); $BASE below is in that upright $WORLD.",
        ]
    return out + [f"; {axes_note(motion)}"]


def write(motion: Motion, options: ExportOptions) -> str:
    name = options.program_name
    ext = _external(motion)
    out_n = scan_output(options, DEFAULT_SCAN_OUTPUT, "number 1-4096")
    joint_moves = joint_move_targets(motion, options)
    e6pos = options.arm is not None
    out = [
        "&ACCESS RVP",
        "&REL 1",
        f"DEF {name}( )",
        "; Laser-profilometer scan path written by scanplan. Save as "
        f"{name}.src (KRL wants the file named after the DEF).",
        "; Targets are T_part_tcp, the TCP's pose in the part's frame: $BASE is the part",
        "; (T_base_part; assumes $WORLD = $ROBROOT, but for an arm hung upside down; calibrate",
        "; it as a BASE_DATA and nothing else changes) and $TOOL the TCP (T_flange_sensor",
        "; moved along the beam).",
        f"; {standoff_note(motion)}.",
        "; X,Y,Z in mm; A,B,C in degrees, A about Z, B about Y', "
        "C about X''. $VEL.CP in m/s, $APO.CDIS in mm.",
        f"; {len(motion.poses)} targets from {motion.n_planned} planned poses, "
        f"{int(motion.pass_start.sum())} scanning runs; each run thinned to the fewest "
        f"targets within {options.chord_tol:g} mm and {np.degrees(options.angle_tol_rad):g} deg",
        "; of the plan. C_DIS blends where $APO.CDIS > 0, capped so a blend cuts the path by",
        "; at most that chord tolerance in a run and by at most "
        f"{options.move_cut_mm:g} mm between runs (a share of",
        f"; the {options.scan.clearance_mm:g} mm clearance the moves were planned with); none "
        "(exact stop) at each run's start and end,",
        "; at the program's ends and before each PTP.",
        (
            "; The program's first target and each run's first target: PTP to the E6POS with"
            " the Status and Turn of the configuration the reach check chose."
            if e6pos and joint_moves
            else "; Each run entered by PTP to the axis angles the reach check chose."
            if joint_moves
            else "; No arm checked: no joint moves."
        ),
        f"; Acquisition: $OUT[{out_n}] = TRUE at each run's first target, FALSE at its last; wire",
        "; it to the sensor's acquisition enable. Setting $OUT stops the advance run, so it",
        "; switches with the robot standing on that target.",
        *_axes_header(motion),
        "  BAS(#INITMOV, 0)",
        f"  $BASE = {_frames((world_base(motion.axes) @ motion.part_pose)[None])[0]}",
        f"  $TOOL = {_frames(options.tool[None])[0]}",
        "  $ADVANCE = 3",
        f"  $ACC.CP = {options.accel_mm_s2 / 1000.0:.6g}",
    ]
    speed = None
    cdis = None
    for i, frame in enumerate(_frames(motion.poses_part)):
        k = int(motion.swath[i])
        if motion.pass_start[i]:
            out.append(f"  ; pass {k} start")
        if motion.speed_mm_s[i] != speed:
            speed = motion.speed_mm_s[i]
            out.append(f"  $VEL.CP = {speed / 1000.0:.6g}")
        blend = float(motion.blend_mm[i])
        if blend > 0 and blend != cdis:
            cdis = blend
            out.append(f"  $APO.CDIS = {blend:.4f}")
        if i in joint_moves and e6pos:  # into the run's configuration
            assert options.arm is not None
            status, turn = status_turn(joint_moves[i], options.arm)
            out.append(f"  PTP {frame[:-1]}{ext[i]},S 'B{status:03b}',T 'B{turn:06b}'}}")
        else:
            if i in joint_moves:  # no arm to say the configuration: axis angles, degrees
                deg = np.degrees(joint_moves[i])
                axes = ",".join(f"A{j + 1} {v:.4f}" for j, v in enumerate(deg))
                out.append(f"  PTP {{{axes}{ext[i]}}}")
            out.append(f"  LIN {frame[:-1]}{ext[i]}}}" + (" C_DIS" if blend > 0 else ""))
        if motion.pass_start[i]:
            out.append(f"  $OUT[{out_n}] = TRUE  ; acquisition on")
        if motion.pass_end[i]:
            out.append(f"  $OUT[{out_n}] = FALSE  ; acquisition off")
            out.append(f"  ; pass {k} end")
    out += ["END", ""]
    return "\n".join(out)


def parse(text: str) -> Parsed:
    rows: list[list[float]] = []
    external: list[list[float]] = []
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
        elif m := _MOVE.match(s):
            items = dict(item.split()[:2] for item in m.group(2).split(",") if item.strip())
            rows.append([float(items[k]) for k in _AXES])
            ext = sorted(
                (int(k[1:]), float(v)) for k, v in items.items() if re.fullmatch(r"E\d", k)
            )
            external.append([v for _, v in ext])
            speeds.append(speed)
            blended.append(m.group(3) is not None)
            tracker.move()
    if not rows:
        raise ValueError("KRL program holds no LIN")
    arr = np.asarray(rows)
    poses = np.tile(np.eye(4), (len(arr), 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("ZYX", arr[:, 3:], degrees=True).as_matrix()
    poses[:, :3, 3] = arr[:, :3]
    axes = read_axes(text)
    values = np.array(external, dtype=np.float64) if axes is not None else None
    if values is not None and values.shape != (len(rows), len(axes.names)):  # type: ignore[union-attr]
        raise ValueError("KRL program: a target without its external axis values (E1..)")
    base = np.linalg.inv(world_base(axes)) @ base  # $BASE is in the upright $WORLD
    poses = sensor_poses(on_axes(base, poses, values, axes), read_standoff(text))
    return Parsed(poses, np.array(tracker.flags), np.array(speeds), np.array(blended), values)
