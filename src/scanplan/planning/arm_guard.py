"""A controller's corrections kept within the arm a plan was fitted to: each pose the
controller proposes on a pass is checked with the arm's inverse kinematics on the branch
the pass is flown on, and a correction the arm cannot follow is scaled back towards the
plan's own pose at that advance (which the arm flies: fitting kept it), down to that pose.

A pass of a fitted plan is one piece of a pass line (fitting splits a line where the arm
gives up poses or flips its configuration, and may turn a piece half a turn about the beam):
`PieceNominal` holds the plan's states along one piece, in the line's frame, and whether the
arm flies it turned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from scanplan.planning.online import pass_state
from scanplan.planning.swaths import Swath, frame_poses
from scanplan.robot.base import Robot, wrap
from scanplan.robot.flown_poses import HALF_TURN
from scanplan.robot.nearest_joints import fit_limits
from scanplan.robot.presets import get_robot
from scanplan.robot.reach import check_reach

# The shares of a refused correction tried in turn before the plan's own pose (0).
CORRECTION_SHARES = (0.5, 0.25, 0.0)
# The most a joint may turn between two poses of a pass (`reach.check_reach`'s jump).
JUMP_DEG = 30.0


@dataclass(frozen=True)
class PieceNominal:
    """One pass of a fitted plan: its line `swath` (view frame), the plan's states (k, n)
    along it (s ascending: (s, h, θ[, φ, l])), and whether the arm flies it turned half a
    turn about the beam."""

    swath: Swath
    states: np.ndarray
    turned: bool = False

    def at(self, s_mm: float) -> np.ndarray:
        """The plan's state at advance `s_mm` (interpolated; the ends held beyond them)."""
        x = self.states
        rest = [float(np.interp(s_mm, x[:, 0], x[:, j])) for j in range(1, x.shape[1])]
        return np.array([s_mm, *rest])

    def nearest(self, s_mm: float) -> int:
        """The index of the plan's state nearest advance `s_mm` (a pose the arm reaches)."""
        return int(np.argmin(np.abs(self.states[:, 0] - s_mm)))

    def poses(self, states: np.ndarray) -> np.ndarray:
        """(k, 4, 4) view-frame sensor poses of (k, n) states on this pass."""
        x = np.atleast_2d(states)
        extra = (x[:, 3], x[:, 4]) if x.shape[1] == 5 else (None, None)
        return frame_poses(self.swath.start_mm, self.swath.u, self.swath.v, *x[:, :3].T, *extra)


@dataclass
class ArmGuard:
    """The arm (`robot` with the sensor at `T_flange_sensor`, the part at `T_base_part` in
    its base) that a view's passes are flown by; `R_view` (4, 4) maps the part frame to the
    view frame the passes are planned in; `pieces` the plan's passes by swath index. `admit`
    is what `closed_loop.drive_passes` asks of each proposed step; `clamped` and `fallbacks`
    count the corrections scaled back and those replaced by the plan's own pose.
    """

    robot: str | Robot
    T_base_part: np.ndarray
    T_flange_sensor: np.ndarray
    R_view: np.ndarray
    pieces: dict[int, PieceNominal]
    clamped: int = 0
    fallbacks: int = 0
    _q: dict[int, np.ndarray] = field(default_factory=dict, repr=False)
    _planned_q: dict[int, np.ndarray] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._arm = get_robot(self.robot)
        self._to_base = self.T_base_part @ np.linalg.inv(self.R_view)
        self._inv_tcp = np.linalg.inv(self.T_flange_sensor)

    def flange(self, index: int, poses: np.ndarray) -> np.ndarray:
        """(k, 4, 4) the flange in the arm's base at view-frame sensor poses of pass `index`."""
        turn = HALF_TURN if self.pieces[index].turned else np.eye(4)
        return self._to_base @ poses @ turn @ self._inv_tcp

    def _reference(self, index: int, s_mm: float) -> np.ndarray:
        """The joints pass `index` is on: the last admitted, else those the arm flies the
        plan's pose nearest `s_mm` with (the pass followed as `check_reach` follows it)."""
        if index in self._q:
            return self._q[index]
        piece = self.pieces[index]
        if index not in self._planned_q:
            flange = self.flange(index, piece.poses(piece.states))
            self._planned_q[index] = check_reach(flange, self._arm).joints
        joints = self._planned_q[index]
        ok = np.flatnonzero(~np.isnan(joints).any(axis=1))
        if not len(ok):
            raise ValueError(f"pass {index}: the arm reaches none of its planned poses")
        near = ok[np.argmin(np.abs(piece.states[ok, 0] - s_mm))]
        return joints[near]

    def _follows(self, index: int, pose: np.ndarray, q_ref: np.ndarray) -> np.ndarray | None:
        """The joints the arm reaches `pose` with on the branch of `q_ref` (in its limits,
        no joint turning more than `JUMP_DEG`, no singularity crossed); None if it cannot."""
        arm = self._arm
        solutions = arm.inverse(self.flange(index, pose[None]))[0]
        cand = solutions[~np.isnan(solutions).any(axis=1)]
        if not len(cand):
            return None
        cand, inside = fit_limits(q_ref + wrap(cand - q_ref), arm.joint_limits)
        cand = cand[inside]
        if not len(cand):
            return None
        q = cand[np.argmin(((cand - q_ref) ** 2).sum(axis=1))]
        if np.abs(q - q_ref).max() > np.radians(JUMP_DEG):
            return None
        terms = arm.singularity_terms(np.stack([q_ref, q]))
        return q if np.array_equal(terms[0] >= 0, terms[1] >= 0) else None

    def admit(self, indices: list[int], states: np.ndarray) -> np.ndarray:
        """(k, n) the states the arm follows, of passes `indices`: each proposed state as it
        is where the arm follows it, else its correction from the plan's state at that
        advance scaled back (`CORRECTION_SHARES`), else the plan's pose nearest there."""
        out = np.array(states, dtype=np.float64)
        for i, index in enumerate(indices):
            piece = self.pieces[index]
            s = float(out[i, 0])
            q_ref = self._reference(index, s)
            q = self._follows(index, piece.poses(out[i])[0], q_ref)
            if q is None:
                nominal = piece.at(s)
                for share in CORRECTION_SHARES:
                    trial = nominal + share * (out[i] - nominal)
                    q = self._follows(index, piece.poses(trial)[0], q_ref)
                    if q is not None:
                        out[i] = trial
                        self.clamped += 1
                        break
                else:
                    k = piece.nearest(s)
                    out[i] = piece.states[k]
                    q = self._planned_q[index][k] if index in self._planned_q else None
                    self.fallbacks += 1
            if q is not None and not np.isnan(q).any():
                self._q[index] = q
        return out


def fitted_pieces(
    lines: list[Swath],
    poses: np.ndarray,
    swath: np.ndarray,
    min_length_mm: float,
    roll: bool = False,
) -> list[PieceNominal]:
    """The passes of a view of a fitted plan as pieces of its pass `lines` (view frame):
    `poses` (m, 4, 4) the view's scanning poses in its frame, `swath` (m,) their pass
    indices. Each pass lies on the line whose plane is nearest its sensor positions, turned
    where its scan axis runs against the line's; its piece of the line runs from its first
    advance to its last, numbered as the pass. A pass shorter than `min_length_mm` is left
    out (a closed loop has nowhere to go on it)."""
    out = []
    for index in np.unique(swath):
        mine = poses[swath == index]
        where = mine[:, :3, 3]
        offsets = [abs(float(np.mean((where - line.start_mm) @ line.v))) for line in lines]
        line = lines[int(np.argmin(offsets))]
        turned = float(np.mean(mine[:, :3, 1] @ line.u)) < 0
        unturned = mine @ HALF_TURN if turned else mine
        states = np.stack([pass_state(line, T, roll) for T in unturned])
        states = states[np.argsort(states[:, 0])]
        s0, s1 = float(states[0, 0]), float(states[-1, 0])
        if s1 - s0 < min_length_mm:
            continue
        piece = Swath(
            int(index),
            line.start_mm + s0 * line.u,
            line.start_mm + s1 * line.u,
            line.u,
            line.v,
            line.band_mm,
        )
        states[:, 0] -= s0
        out.append(PieceNominal(piece, states, turned))
    return out
