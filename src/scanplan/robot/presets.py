"""The arms `--robot` knows by name, and user TOML files for any other OPW arm.

Each preset is the controller's own frames: `T_base_flange` as its pendant shows it, and
its motion limits (`motion_limits`) for the cycle time.
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from scipy.spatial.transform import Rotation

from scanplan.core.cycle import (
    ACCEL_MM_S2,
    ANGULAR_ACCEL_DEG_S2,
    ANGULAR_SPEED_DEG_S,
    NOMINAL,
    MotionLimits,
    joint_accels,
)
from scanplan.core.limits import (
    JOINT_DEG,
    LENGTH_MM,
    LINK_MM,
    SIGNED_LENGTH_MM,
    SPEED_MM_S,
    TCP_ACCEL_MM_S2,
    TURN_ACCEL_DEG_S2,
    TURN_SPEED_DEG_S,
    Limit,
    in_range,
)
from scanplan.core.paths import read_regular, regular_file
from scanplan.robot.base import Robot
from scanplan.robot.opw import OPWRobot
from scanplan.robot.ur import UR_MODELS


def _pose(x: float, y: float, z: float, a: float, b: float, c: float) -> np.ndarray:
    """4x4 from mm and KUKA A, B, C degrees (intrinsic ZYX), as `--part-pose` reads them."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("ZYX", [a, b, c], degrees=True).as_matrix()
    T[:3, 3] = x, y, z
    return T


def _limits(*pairs: tuple[float, float]) -> tuple[tuple[float, float], ...]:
    return tuple((float(np.radians(lo)), float(np.radians(hi))) for lo, hi in pairs)


_DEG90 = np.pi / 2

OPW_PRESETS: dict[str, OPWRobot] = {
    # KUKA KR 6 R900 sixx (KR AGILUS). Lengths from ROS-Industrial kuka_experimental,
    # kuka_kr6_support/urdf/kr6r900sixx_macro.xacro (joint origins 400, 25, 455, 35, 420,
    # 80 mm), which match KUKA's dimension drawing; offsets and signs as ROS-Industrial's
    # opw_kinematics files for the KR 6 family (A2 = -90° is the upper arm upright).
    # Limits: KUKA data sheet KR 6 R900 sixx, A1 ±170°, A2 -190/+45°, A3 -120/+156°,
    # A4 ±185°, A5 ±120°, A6 ±350°. $FLANGE has X out of the flange: the paper's tool
    # frame turned -90° about Y.
    "kr6-r900": OPWRobot(
        "kr6-r900",
        a1=25.0,
        a2=-35.0,
        b=0.0,
        c1=400.0,
        c2=455.0,
        c3=420.0,
        c4=80.0,
        offsets=(0.0, -_DEG90, 0.0, 0.0, 0.0, 0.0),
        sign=(-1, 1, 1, -1, 1, -1),
        limits=_limits((-170, 170), (-190, 45), (-120, 156), (-185, 185), (-120, 120), (-350, 350)),
        flange=_pose(0, 0, 0, 0, -90, 0),
    ),
    # ABB IRB 2400/16 (the /10 has the same axes). Parameters as Brandstötter et al. (2014)
    # list them and ROS-Industrial's opw_kinematics `makeIrb2400_10`: a1 100, a2 -135,
    # c1 615, c2 705, c3 755, c4 85 mm. Limits: ABB product specification IRB 2400, axis 1
    # ±180°, 2 -100/+110°, 3 -60/+65°, 4 ±200°, 5 ±120°, 6 ±400°. tool0 has Z out of the
    # flange, as the paper's tool frame.
    "irb2400": OPWRobot(
        "irb2400",
        a1=100.0,
        a2=-135.0,
        b=0.0,
        c1=615.0,
        c2=705.0,
        c3=755.0,
        c4=85.0,
        offsets=(0.0, 0.0, -_DEG90, 0.0, 0.0, 0.0),
        limits=_limits((-180, 180), (-100, 110), (-60, 65), (-200, 200), (-120, 120), (-400, 400)),
    ),
    # FANUC LR Mate 200iD (717 mm reach). Lengths from ROS-Industrial fanuc,
    # fanuc_lrmate200id_support/urdf/lrmate200id_macro.xacro (330, 50, 330, 35, 335, 80 mm).
    # Base = Fanuc's World frame, whose origin is on J1 at the height of J2 (330 mm above
    # the mounting face); the faceplate frame has Z out of the flange. J3 is Fanuc's,
    # measured from the horizontal. Limits: FANUC LR Mate 200iD data sheet (J1 340°, J2
    # 245°, J3 420°, J4 380°, J5 250°, J6 720°), split into lower/upper as in that URDF:
    # J1 ±170°, J2 -100/+145°, J3 -140/+280°, J4 ±190°, J5 ±125°, J6 ±360°.
    "lrmate200id": OPWRobot(
        "lrmate200id",
        a1=50.0,
        a2=-35.0,
        b=0.0,
        c1=330.0,
        c2=330.0,
        c3=335.0,
        c4=80.0,
        offsets=(0.0, 0.0, -_DEG90, 0.0, 0.0, 0.0),
        sign=(1, 1, -1, -1, -1, -1),
        limits=_limits(
            (-170, 170), (-100, 145), (-140, 280), (-190, 190), (-125, 125), (-360, 360)
        ),
        base=_pose(0, 0, -330, 0, 0, 0),
        flange=_pose(0, 0, 0, 180, 0, 0),
        j3_from_horizontal=True,
    ),
}

ROBOT_NAMES: tuple[str, ...] = (*UR_MODELS, *OPW_PRESETS)


def _motion(
    name: str, speed_mm_s: float, joints_deg_s: tuple[float, ...], source: str
) -> MotionLimits:
    """Data-sheet speeds; the accelerations and reorientation limits no data sheet gives are
    `scanplan.core.cycle`'s documented choices."""
    return MotionLimits(
        name,
        speed_mm_s=speed_mm_s,
        accel_mm_s2=ACCEL_MM_S2,
        angular_speed_deg_s=ANGULAR_SPEED_DEG_S,
        angular_accel_deg_s2=ANGULAR_ACCEL_DEG_S2,
        joint_speed_deg_s=joints_deg_s,
        joint_accel_deg_s2=joint_accels(joints_deg_s),
        source=source,
    )


# Joint speeds as the makers' data sheets give them, checked against the ROS-Industrial
# descriptions that cite those sheets: universal_robot ur_description/config/<model>/
# joint_limits.yaml (UR e-Series user manuals 5.8), kuka_experimental kr6r900sixx_macro.xacro,
# abb irb2400_macro.xacro, fanuc lrmate200id_macro.xacro. TCP speed: UR e-Series data sheets
# (typical TCP speed 1 m/s); the industrial arms: 2 m/s, the linear speed their controllers
# accept in programs (KRL $VEL.CP, FANUC linear motion), not a data-sheet figure.
_UR = "UR e-Series data sheet (TCP 1 m/s, joint speeds)"
MOTION_LIMITS: dict[str, MotionLimits] = {
    "ur3e": _motion("ur3e", 1000.0, (180.0,) * 3 + (360.0,) * 3, _UR),
    "ur5e": _motion("ur5e", 1000.0, (180.0,) * 6, _UR),
    "ur10e": _motion("ur10e", 1000.0, (120.0,) * 2 + (180.0,) * 4, _UR),
    "kr6-r900": _motion(
        "kr6-r900",
        2000.0,
        (360.0, 300.0, 360.0, 381.0, 388.0, 615.0),
        "KUKA KR 6 R900 sixx data sheet (axis speeds A1-A6)",
    ),
    "irb2400": _motion(
        "irb2400",
        2000.0,
        (150.0, 150.0, 150.0, 360.0, 360.0, 450.0),
        "ABB IRB 2400 product specification (axis speeds 1-6)",
    ),
    "lrmate200id": _motion(
        "lrmate200id",
        2000.0,
        (450.0, 380.0, 520.0, 550.0, 545.0, 1000.0),
        "FANUC LR Mate 200iD data sheet (J1-J6 speeds)",
    ),
}

Six = Annotated[list[float], Field(min_length=6, max_length=6)]
SixAngles = Annotated[
    list[Annotated[float, in_range(JOINT_DEG)]], Field(min_length=6, max_length=6)
]


class RobotFile(BaseModel):
    """A user's OPW arm: lengths in mm (the paper's names), angles in degrees."""

    model_config = ConfigDict(extra="forbid")
    name: str = "custom"
    a1: Annotated[float, in_range(SIGNED_LENGTH_MM)]
    a2: Annotated[float, in_range(SIGNED_LENGTH_MM)]
    b: Annotated[float, in_range(SIGNED_LENGTH_MM)] = 0.0
    c1: Annotated[float, in_range(SIGNED_LENGTH_MM)]
    c2: Annotated[float, in_range(LINK_MM)]
    c3: Annotated[float, in_range(SIGNED_LENGTH_MM)]
    c4: Annotated[float, in_range(Limit(0.0, LENGTH_MM.hi, "mm"))]
    offsets_deg: SixAngles = Field(default_factory=lambda: [0.0] * 6)
    sign: Annotated[list[Literal[-1, 1]], Field(min_length=6, max_length=6)] = [1, 1, 1, 1, 1, 1]
    limits_deg: Annotated[
        list[
            Annotated[
                list[Annotated[float, in_range(JOINT_DEG)]], Field(min_length=2, max_length=2)
            ]
        ],
        Field(min_length=6, max_length=6),
    ]
    base: Six = Field(default_factory=lambda: [0.0] * 6)  # x,y,z mm, A,B,C deg
    flange: Six = Field(default_factory=lambda: [0.0] * 6)
    j3_from_horizontal: bool = False
    # Motion limits for the cycle time; the nominal arm's where the file gives none.
    speed_mm_s: Annotated[float, in_range(SPEED_MM_S)] = NOMINAL.speed_mm_s
    accel_mm_s2: Annotated[float, in_range(TCP_ACCEL_MM_S2)] = NOMINAL.accel_mm_s2
    angular_speed_deg_s: Annotated[float, in_range(TURN_SPEED_DEG_S)] = NOMINAL.angular_speed_deg_s
    angular_accel_deg_s2: Annotated[float, in_range(TURN_ACCEL_DEG_S2)] = (
        NOMINAL.angular_accel_deg_s2
    )
    joint_speed_deg_s: Annotated[
        list[Annotated[float, in_range(TURN_SPEED_DEG_S)]], Field(min_length=6, max_length=6)
    ] = Field(default_factory=lambda: list(NOMINAL.joint_speed_deg_s))
    joint_accel_deg_s2: Annotated[
        list[Annotated[float, in_range(TURN_ACCEL_DEG_S2)]], Field(min_length=6, max_length=6)
    ] = Field(default_factory=lambda: list(NOMINAL.joint_accel_deg_s2))

    @model_validator(mode="after")
    def _finite_and_ordered(self) -> RobotFile:
        for i, (lo, hi) in enumerate(self.limits_deg):
            if not lo < hi:
                raise ValueError(f"limits_deg joint {i + 1}: lower {lo} must be < upper {hi}")
        # Where a cell's numbers can be: 1e308 is finite, but no arm's.
        for name in ("base", "flange"):
            for v in getattr(self, name)[:3]:
                SIGNED_LENGTH_MM.check(v, f"{name} x,y,z")
            for v in getattr(self, name)[3:]:
                JOINT_DEG.check(v, f"{name} A,B,C")
        # The forearm (elbow to wrist centre) is a link as c2 is: a zero one has no elbow.
        LINK_MM.check(math.hypot(self.a2, self.c3), "the forearm's length hypot(a2, c3)")
        return self

    def motion_limits(self, source: str) -> MotionLimits:
        return MotionLimits(
            self.name,
            speed_mm_s=self.speed_mm_s,
            accel_mm_s2=self.accel_mm_s2,
            angular_speed_deg_s=self.angular_speed_deg_s,
            angular_accel_deg_s2=self.angular_accel_deg_s2,
            joint_speed_deg_s=tuple(self.joint_speed_deg_s),
            joint_accel_deg_s2=tuple(self.joint_accel_deg_s2),
            source=source,
        )

    def to_robot(self) -> OPWRobot:
        return OPWRobot(
            self.name,
            a1=self.a1,
            a2=self.a2,
            b=self.b,
            c1=self.c1,
            c2=self.c2,
            c3=self.c3,
            c4=self.c4,
            offsets=tuple(float(np.radians(v)) for v in self.offsets_deg),
            sign=tuple(self.sign),
            limits=_limits(*((lo, hi) for lo, hi in self.limits_deg)),
            base=_pose(*self.base),
            flange=_pose(*self.flange),
            j3_from_horizontal=self.j3_from_horizontal,
        )


MAX_ROBOT_FILE_BYTES = 1024**2


def load_robot_file(path: str | Path) -> OPWRobot:
    """A TOML file of OPW parameters -> OPWRobot; ValueError naming the file and field."""
    return _robot_file(path).to_robot()


def _robot_file(path: str | Path) -> RobotFile:
    path = Path(path)
    content = read_regular(path, "robot file", MAX_ROBOT_FILE_BYTES, "not a robot's parameters")
    try:
        data = tomllib.loads(content.decode())
    except (UnicodeDecodeError, tomllib.TOMLDecodeError, RecursionError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"robot file {path} cannot be parsed: {first}") from None
    try:
        return RobotFile.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        where = "".join(f"{p}: " if i == 0 else f".{p}" for i, p in enumerate(err["loc"]))
        where = where.replace(": .", ".").rstrip(" :")
        msg = str(err["msg"]).removeprefix("Value error, ")
        raise ValueError(f"robot file {path}: {where + ': ' if where else ''}{msg}") from None


def get_robot(robot: str | Path | Robot) -> Robot:
    """A preset name (ur3e, ur5e, ur10e, kr6-r900, irb2400, lrmate200id), a TOML file of
    OPW parameters, or a Robot (returned as is)."""
    if not isinstance(robot, str | Path):
        return robot
    key = str(robot).lower()
    if key in UR_MODELS:
        return UR_MODELS[key]
    if key in OPW_PRESETS:
        return OPW_PRESETS[key]
    if key.endswith(".toml"):
        regular_file(robot, "robot file")  # a directory, a FIFO, a device: said as such
        return load_robot_file(robot)
    raise ValueError(
        f"unknown robot {str(robot)!r}; choose one of {', '.join(ROBOT_NAMES)} or a .toml file"
    )


def motion_limits(robot: str | Path | Robot) -> MotionLimits:
    """The arm's motion limits for the cycle time: a preset's from its data sheet, a TOML
    file's own (the nominal arm's where it gives none); a Robot by its preset name, else the
    nominal arm's. ValueError for a name that is neither a preset nor a file."""
    if not isinstance(robot, str | Path):
        return MOTION_LIMITS.get(robot.name, NOMINAL)
    key = str(robot).lower()
    if key in MOTION_LIMITS:
        return MOTION_LIMITS[key]
    if key.endswith(".toml"):
        regular_file(robot, "robot file")  # a directory, a FIFO, a device: said as such
        return _robot_file(robot).motion_limits(f"robot file {robot} (nominal where not given)")
    raise ValueError(
        f"unknown robot {str(robot)!r}; choose one of {', '.join(ROBOT_NAMES)} or a .toml file"
    )
