"""What would lift what bound an arm's plan: the numbers of its record (the poses given up
by cause, how far beyond its reach) turned into what to change in the cell.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from scanplan.robot.base import pose_arg

# The share of the surface seen only by views an arm cannot fly from where it stands
# (`pipeline._not_flown`) from which a positioner is suggested first.
NOT_FLOWN_HINT = 0.02
# A sensor whose beam is this far off the flange's axis is mounted across it: said, since
# on a KUKA (x out of the flange) `--tcp 0,0,90,0,0,0` is a sideways bracket.
ACROSS_FLANGE_DEG = 45.0


def facing(axis: list[float]) -> str:
    """A view's axis as the side of the part it faces: '+y', '-x (40° up)', 'up'."""
    x, y, z = axis
    if z >= 0.9:
        return "up"
    k = 0 if abs(x) >= abs(y) else 1
    side = f"{'+' if axis[k] >= 0 else '-'}{'xy'[k]}"
    up = round(math.degrees(math.asin(max(-1.0, min(1.0, z)))))
    return side if abs(up) < 20 else f"{side} ({up}° up)"


def across_flange(robot: str, flange_axis: np.ndarray, tcp: np.ndarray) -> str | None:
    """A note when the sensor on `tcp` (T_flange_sensor, mm) looks more than
    ACROSS_FLANGE_DEG off the flange's axis (`Robot.flange_axis`), giving the --tcp of the
    sensor as far out straight along it; None when it looks along it."""
    tcp, axis = np.asarray(tcp, dtype=np.float64), np.asarray(flange_axis, dtype=np.float64)
    off = math.degrees(math.acos(float(np.clip(tcp[:3, 2] @ axis, -1.0, 1.0))))
    if off <= ACROSS_FLANGE_DEG:
        return None
    straight = np.eye(4)
    straight[:3, :3] = Rotation.align_vectors([axis], [[0.0, 0.0, 1.0]])[0].as_matrix()
    out = float(np.linalg.norm(tcp[:3, 3]))
    straight[:3, 3] = out * axis
    name = "xyz"[int(np.argmax(np.abs(axis)))] if np.abs(axis).max() > 0.999 else None
    which = f"its flange's {name} axis points out of it" if name else "its flange's axis"
    return (
        f"the sensor's beam is {off:.0f}° off the flange's axis ({robot}: {which}); the "
        f"sensor {out:g} mm straight out, looking along it, is --tcp {pose_arg(straight)}"
    )


def why_not(view: dict) -> str:
    """What keeps an arm from a view's scanning poses (`pipeline._not_flown`'s record)."""
    parts = [f"{view['scanning_poses']} poses"]
    if view["out_of_reach"]:
        beyond = view.get("beyond_reach_mm")
        far = f", the farthest {beyond:.0f} mm beyond its reach" if beyond and beyond > 0 else ""
        parts.append(f"{view['out_of_reach']} out of reach{far}")
    if view["beyond_joint_limits"]:
        parts.append(f"{view['beyond_joint_limits']} beyond the joint limits")
    if len(parts) == 1:
        parts.append("reached within the limits: its links or the sensor body meet the cell")
    return ": ".join([parts[0], ", ".join(parts[1:])])


def what_would_help(record: dict) -> list[str]:
    """What the numbers of an arm's record (`fit.RobotFit.record`) say would lift what bound:
    the largest cause of poses given up first; an axis the cell has is not suggested."""
    axes = record.get("external_axes") or {}
    track, turntable = axes.get("track") is not None, axes.get("turntable") is not None
    far = ["an arm reaching that much farther", "a longer track" if track else "a linear track"]
    far += [] if turntable else ["a turntable bringing the far side round"]
    causes: dict[str, int] = {}
    for by in record.get("given_up_by_cause", {}).values():
        for cause, count in by.items():
            causes[cause] = causes.get(cause, 0) + int(count)
    out = []
    missed = record.get("free_views_not_flown") or []
    share = float(record.get("in_spec_not_flown", 0.0))
    if missed and share >= NOT_FLOWN_HINT:
        sides = ", ".join(dict.fromkeys(facing(v["axis"]) for v in missed))
        reach = sum(v["out_of_reach"] for v in missed) >= sum(
            v["beyond_joint_limits"] for v in missed
        )
        bound = "out of its reach" if reach else "beyond its joint limits"
        helps = far[-1] if not turntable else "an arm reaching farther"
        out.append(
            f"{share:.3f} of the surface is seen only from {sides} of the part, where the "
            f"sensor is {bound} from where the arm stands: {helps}"
        )
    for cause, count in sorted(causes.items(), key=lambda c: -c[1]):
        if cause == "reach":
            beyond = record.get("beyond_reach_mm")
            if beyond is not None and beyond > 0:
                out.append(
                    f"{count} poses out of reach, the farthest {beyond:.0f} mm beyond the "
                    f"arm's horizontal reach: {', '.join(far[:-1])} or {far[-1]}"
                )
            else:
                out.append(
                    f"{count} poses out of reach at their height or tilt (within the arm's "
                    "horizontal reach): the part higher or lower (--part-pose), or a "
                    "positioner tilting it"
                )
        elif cause == "joint limits":
            turn = "" if turntable else "a turntable turning the part, or "
            out.append(
                f"{count} poses beyond the joint limits: {turn}the arm placed elsewhere "
                "(--part-pose)"
            )
        elif cause.startswith("link in"):
            what = cause.removeprefix("link in ")
            out.append(
                f"{count} poses put an arm link within the clearance of {what}: the part "
                "raised or turned (--part-pose, a riser), or a positioner"
            )
        elif cause == "sensor on a joint move":
            out.append(
                f"{count} poses on passes whose joint move in swings the sensor body into the "
                "cell at every height tried: the arm placed elsewhere (--part-pose)"
            )
        else:
            out.append(f"{count} poses on passes no joint move reaches clear of the cell")
    return out


__all__ = ["NOT_FLOWN_HINT", "facing", "what_would_help", "why_not"]
