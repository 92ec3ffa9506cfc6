"""Universal Robots URScript: `movel` with blend radii through the thinned targets, metres and
rotation vectors; the acquisition switched by a standard digital output around each pass."""

from __future__ import annotations

import re

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.robot.export.axes_lines import axes_note
from scanplan.robot.export.common import (
    ExportOptions,
    Motion,
    Parsed,
    PassTracker,
    floats,
    read_standoff,
    scan_output,
    sensor_poses,
    standoff_note,
)
from scanplan.robot.export.joint_moves import (
    JOINT_ACCEL_DEG_S2,
    JOINT_SPEED_DEG_S,
    joint_move_targets,
)
from scanplan.robot.export.rotations import poses_from_parts

SUFFIX = ".script"
DEFAULT_SCAN_OUTPUT = "0"  # standard digital output 0
# movel(pose_trans(feature, p[...]), ...): a target in the part's feature frame.
_MOVEL = re.compile(
    r"movel\(pose_trans\(feature,\s*p\[([^\]]*)\]\),\s*a=([^,]+),\s*v=([^,]+),\s*r=([^)]+)\)"
)
_FEATURE = re.compile(r"^feature\s*=\s*p\[([^\]]*)\]")
# An indexed turntable (UR controllers drive no external axes): a pulse on this standard
# digital output steps it to its next angle, this standard input says it stands there.
TURNTABLE_OUTPUT = 7
TURNTABLE_INPUT = 7
_TURN = re.compile(r"#\s*turntable to ([-+0-9.eE]+) deg")


def _check_indexed(motion: Motion) -> None:
    """A URScript program drives a turntable indexed between views, and nothing else."""
    if motion.axes is None:
        return
    if motion.axes.track is not None:
        raise ValueError(
            "URScript: a UR controller drives no external axes, and a track moves with the "
            "arm: export the plan as ros or csv, or plan it without --track"
        )


def _turntable_lines(angle: float, feature: str) -> list[str]:
    """Index the turntable to `angle` (its controller holds the angles in order) and set
    the part's frame where it now stands."""
    return [
        f"  # turntable to {angle:.6f} deg: pulse output {TURNTABLE_OUTPUT}, wait for input "
        f"{TURNTABLE_INPUT}",
        f"  set_standard_digital_out({TURNTABLE_OUTPUT}, True)",
        f"  while not get_standard_digital_in({TURNTABLE_INPUT}):",
        "    sync()",
        "  end",
        f"  set_standard_digital_out({TURNTABLE_OUTPUT}, False)",
        f"  feature = {feature}",
    ]


def _poses_m(T: np.ndarray) -> list[str]:
    """`p[x, y, z, rx, ry, rz]` per pose of (n, 4, 4) mm poses."""
    values = np.concatenate(
        [T[:, :3, 3] / 1000.0, Rotation.from_matrix(T[:, :3, :3]).as_rotvec()], axis=1
    )
    # 9 decimals in metres = 1 nm: the file never limits accuracy, the controller does.
    return ["p[" + ", ".join(f"{v:.9f}" for v in row) + "]" for row in values]


def write(motion: Motion, options: ExportOptions) -> str:
    _check_indexed(motion)
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
    ]
    features = _poses_m(motion.part_poses())
    steps = np.zeros(len(motion.poses), bool)
    if motion.external is not None:
        steps = np.r_[True, np.abs(np.diff(motion.external[:, 0])) > 1e-9]
        angles = ", ".join(f"{a:g}" for a in motion.external[steps, 0])
        out += [
            "# No external axes on a UR controller: the part lies on an indexed turntable. Before",
            f"# each view the program pulses standard digital output {TURNTABLE_OUTPUT} (the "
            "turntable's controller steps to its",
            f"# next angle: {angles} deg, in order) and waits for standard digital input "
            f"{TURNTABLE_INPUT}",
            "# (in position), the arm standing; `feature` is then the part where it stands.",
            f"# {axes_note(motion)}",
        ]
    out += [
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
        if steps[i]:
            assert motion.external is not None
            out += _turntable_lines(float(motion.external[i, 0]), features[i])
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
    features: list[np.ndarray] = []
    angles: list[float] = []
    angle = None
    feature = np.eye(4)
    tracker = PassTracker()
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("#"):
            tracker.line(s)
            if t := _TURN.match(s):
                angle = float(t.group(1))
            continue
        if f := _FEATURE.match(s):
            x = floats(f.group(1))
            feature = poses_from_parts(np.array([x[:3]]) * 1000.0, Rotation.from_rotvec([x[3:]]))[0]
            continue
        m = _MOVEL.search(s)
        if m:
            values.append([*floats(m.group(1)), *(float(m.group(j)) for j in (2, 3, 4))])
            features.append(feature)
            angles.append(float("nan") if angle is None else angle)
            tracker.move()
    if not values:
        raise ValueError("URScript program holds no movel")
    arr = np.asarray(values)
    poses = np.array(features) @ poses_from_parts(
        arr[:, :3] * 1000.0, Rotation.from_rotvec(arr[:, 3:6])
    )
    poses = sensor_poses(poses, read_standoff(text))
    external = None if angle is None else np.array(angles)[:, None]
    return Parsed(poses, np.array(tracker.flags), arr[:, 7] * 1000.0, arr[:, 8] > 0, external)
