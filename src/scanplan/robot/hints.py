"""What would lift what bound an arm's plan: the numbers of its record (the poses given up
by cause, how far beyond its reach) turned into what to change in the cell.
"""

from __future__ import annotations


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
        else:
            out.append(f"{count} poses on passes no joint move reaches clear of the cell")
    return out


__all__ = ["what_would_help"]
