"""Robot arms: kinematics (UR closed form, OPW arms), reach checks and part placement.

`get_robot` turns a preset name or a TOML file into a `Robot`; `check_reach` follows a
flange path with any of them; `place` (in `scanplan.robot.place`) searches the part's pose.
"""

from scanplan.robot.base import Robot
from scanplan.robot.opw import OPWRobot
from scanplan.robot.presets import (
    MOTION_LIMITS,
    OPW_PRESETS,
    ROBOT_NAMES,
    get_robot,
    load_robot_file,
    motion_limits,
)
from scanplan.robot.reach import ReachReport, check_reach
from scanplan.robot.ur import (
    UR_MODELS,
    URModel,
    forward_kinematics,
    get_model,
    inverse_kinematics,
    singularity_margins,
)

__all__ = [
    "MOTION_LIMITS",
    "OPW_PRESETS",
    "ROBOT_NAMES",
    "UR_MODELS",
    "OPWRobot",
    "ReachReport",
    "Robot",
    "URModel",
    "check_reach",
    "forward_kinematics",
    "get_model",
    "get_robot",
    "inverse_kinematics",
    "load_robot_file",
    "motion_limits",
    "singularity_margins",
]
