"""Perturbations of a plan's world, seeded: the real part is never the CAD.

Three sources, each optional, parsed from one spec string (`Perturbation.parse`):
- placement error (`place:2mm,1deg`): a rigid transform of the part about the centre of its
  bounds, translation per axis and rotation vector per axis drawn from a normal of that σ
  (or, written `±2mm`, uniform within those bounds); the plan's poses stay nominal;
- as-built deviation (`warp:1mm@200mm`): a smooth random field along the surface normal, a
  sum of a few Fourier modes of that wavelength in random 3-D directions, scaled to that RMS
  amplitude; and a uniform scale about the bounds' centre (`scale:0.1%`, σ);
- robot path error (`path:0.1mm,0.05deg`): independent pose noise on every pose of the path.

A `Trial` is one seeded draw: it warps a mesh's vertices and perturbs poses. Everything here
is arrays; a zero σ leaves its arrays bit-for-bit unchanged.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from scanplan.core.limits import (
    LENGTH_MM,
    PERTURB_DEG,
    PERTURB_MM,
    PERTURB_SCALE_PERCENT,
    Limit,
)

# Enough random modes for the field to look irregular, few enough to stay one wavelength smooth.
WARP_MODES = 8

_LENGTH = r"(\+-|±)?(\d+(?:\.\d*)?|\.\d+)(mm|m|um)"
_ANGLE = r"(\+-|±)?(\d+(?:\.\d*)?|\.\d+)(deg|mrad)"
_TO_MM = {"mm": 1.0, "m": 1000.0, "um": 1e-3}
_TO_DEG = {"deg": 1.0, "mrad": 180.0 / np.pi / 1000.0}
GRAMMAR = (
    "place:2mm,1deg;warp:1mm@200mm;scale:0.1%;path:0.1mm,0.05deg "
    "(terms optional, σ of a normal; ±2mm: uniform bounds)"
)


@dataclass(frozen=True)
class Spread:
    """A zero-mean error: σ of a normal, or the half-width of a uniform if `uniform`."""

    size: float = 0.0
    uniform: bool = False

    def draw(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        if self.size == 0.0:
            return np.zeros(shape)
        if self.uniform:
            return rng.uniform(-self.size, self.size, shape)
        return rng.normal(0.0, self.size, shape)

    def text(self, unit: str) -> str:
        return f"{'±' if self.uniform else ''}{self.size:g}{unit}"


@dataclass(frozen=True)
class Perturbation:
    """The perturbation model; lengths mm, angles degrees, scale a fraction."""

    place_mm: Spread = Spread()
    place_deg: Spread = Spread()
    warp_mm: float = 0.0
    warp_wavelength_mm: float = 200.0
    scale: Spread = Spread()
    path_mm: Spread = Spread()
    path_deg: Spread = Spread()

    @classmethod
    def parse(cls, text: str) -> Perturbation:
        """`place:2mm,1deg;warp:1mm@200mm;scale:0.1%;path:0.1mm,0.05deg`, any subset in
        any order. Raises ValueError naming the bad term."""
        fields: dict[str, object] = {}
        seen: set[str] = set()
        terms = [t.strip() for t in text.split(";") if t.strip()]
        if not terms:
            raise ValueError(f"--perturb {text!r} is empty; expected {GRAMMAR}")
        for term in terms:
            key, _, value = term.partition(":")
            key, value = key.strip().lower(), value.replace(" ", "")
            if key in seen:
                raise ValueError(f"--perturb: {_shown(key)!r} given twice")
            seen.add(key)
            try:
                fields.update(_parse_term(key, value))
            except ValueError as exc:
                raise ValueError(f"--perturb term {_shown(term)!r}: {exc}") from None
        return cls(**fields)  # type: ignore[arg-type]

    @property
    def is_zero(self) -> bool:
        return all(
            s == 0.0
            for s in (
                self.place_mm.size,
                self.place_deg.size,
                self.warp_mm,
                self.scale.size,
                self.path_mm.size,
                self.path_deg.size,
            )
        )

    def text(self) -> str:
        """The canonical spec string (parses back to this model)."""
        return (
            f"place:{self.place_mm.text('mm')},{self.place_deg.text('deg')};"
            f"warp:{self.warp_mm:g}mm@{self.warp_wavelength_mm:g}mm;"
            f"scale:{'±' if self.scale.uniform else ''}{100 * self.scale.size:g}%;"
            f"path:{self.path_mm.text('mm')},{self.path_deg.text('deg')}"
        )

    def trial(self, seed: int, index: int) -> Trial:
        """Trial `index` of a seeded run: the same (seed, index) always draws the same."""
        rng = np.random.default_rng([seed, index])
        # Fixed draw order, every term drawn even at zero: a term's draw never shifts another's.
        place_t = self.place_mm.draw(rng, (3,))
        place_r = np.radians(self.place_deg.draw(rng, (3,)))
        directions = rng.normal(size=(WARP_MODES, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        phases = rng.uniform(0.0, 2.0 * np.pi, WARP_MODES)
        scale = float(self.scale.draw(rng, (1,))[0])
        path_seed = int(rng.integers(2**63))
        return Trial(self, place_t, place_r, directions, phases, scale, path_seed)


def _shown(text: str, most: int = 40) -> str:
    """A user's text as a message quotes it: a 400-digit number cut short."""
    return text if len(text) <= most else f"{text[: most - 3]}..."


def _magnitude(digits: str, unit: str, units: dict[str, float], limit: Limit, what: str) -> float:
    """`digits` in `unit`, converted by `units`, or a ValueError naming `what` and `limit`
    (a 400-digit σ parses as inf and would run on a part gone to infinity)."""
    value = float(digits) * units[unit]
    if not limit.contains(value):
        shown = f"{digits}{unit}" if len(digits) <= 20 else f"a number of {len(digits)} digits"
        raise ValueError(f"{what} {shown} is not in {limit}")
    return value


def _spread(
    match: re.Match[str], at: int, units: dict[str, float], limit: Limit, what: str
) -> Spread:
    """The Spread of groups at, at + 1, at + 2 (±, number, unit) of `match`; none if absent."""
    sign, digits, unit = match.group(at, at + 1, at + 2)
    if digits is None:
        return Spread()
    return Spread(_magnitude(digits, unit, units, limit, what), uniform=bool(sign))


def _parse_term(key: str, value: str) -> dict[str, object]:
    if key in ("place", "path"):
        m = re.fullmatch(f"{_LENGTH}(?:,{_ANGLE})?", value)
        if not m:
            example = "2mm,1deg" if key == "place" else "0.1mm,0.05deg"
            raise ValueError(f"expected a length and optionally an angle, e.g. {example}")
        return {
            f"{key}_mm": _spread(m, 1, _TO_MM, PERTURB_MM, "the length"),
            f"{key}_deg": _spread(m, 4, _TO_DEG, PERTURB_DEG, "the angle"),
        }
    if key == "warp":
        m = re.fullmatch(rf"{_LENGTH}@(\d+(?:\.\d*)?|\.\d+)(mm|m)", value)
        if not m or m.group(1):
            raise ValueError("expected an RMS amplitude and a wavelength, e.g. 1mm@200mm")
        return {
            "warp_mm": _spread(m, 1, _TO_MM, PERTURB_MM, "the amplitude").size,
            "warp_wavelength_mm": _magnitude(
                m.group(4), m.group(5), _TO_MM, LENGTH_MM, "the wavelength"
            ),
        }
    if key == "scale":
        m = re.fullmatch(r"(\+-|±)?(\d+(?:\.\d*)?|\.\d+)(%)", value)
        if not m:
            raise ValueError("expected a percentage, e.g. 0.1%")
        percent = _spread(m, 1, {"%": 1.0}, PERTURB_SCALE_PERCENT, "the scale error")
        return {"scale": Spread(percent.size / 100.0, uniform=percent.uniform)}
    raise ValueError(f"unknown term {_shown(key)!r} (place, warp, scale, path)")


def bounds_centre(vertices: np.ndarray) -> np.ndarray:
    """(3,) the centre of (v, 3) vertices' bounds: where a part is turned and scaled about."""
    return vertices.min(axis=0) / 2 + vertices.max(axis=0) / 2


def rotation_matrix(rotvec_rad: np.ndarray) -> np.ndarray:
    """(..., 3) rotation vectors -> (..., 3, 3) rotation matrices (Rodrigues)."""
    rotvec_rad = np.asarray(rotvec_rad, float)
    angle = np.linalg.norm(rotvec_rad, axis=-1)[..., None, None]
    safe = np.where(angle > 0, angle, 1.0)
    k = rotvec_rad / safe[..., 0]
    kx = np.zeros(rotvec_rad.shape[:-1] + (3, 3))
    kx[..., 0, 1], kx[..., 0, 2] = -k[..., 2], k[..., 1]
    kx[..., 1, 0], kx[..., 1, 2] = k[..., 2], -k[..., 0]
    kx[..., 2, 0], kx[..., 2, 1] = -k[..., 1], k[..., 0]
    eye = np.broadcast_to(np.eye(3), kx.shape)
    return eye + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)


@dataclass(frozen=True)
class Trial:
    """One draw of a `Perturbation`. place_t_mm (3,), place_rotvec_rad (3,): the placement
    error; directions (m, 3), phases (m,): the warp's modes; scale: the fraction the part
    grows by; path_seed: the path noise's stream."""

    model: Perturbation
    place_t_mm: np.ndarray
    place_rotvec_rad: np.ndarray
    directions: np.ndarray
    phases: np.ndarray
    scale: float
    path_seed: int

    def warp_mm(self, points: np.ndarray) -> np.ndarray:
        """(k,) the as-built deviation along the normal at (k, 3) points of the part, mm."""
        if self.model.warp_mm == 0.0:
            return np.zeros(len(points))
        k = 2.0 * np.pi / self.model.warp_wavelength_mm
        modes = np.cos(points @ self.directions.T * k + self.phases)
        # Each mode has RMS 1/√2 over space: √(2/m) makes the sum's RMS the amplitude.
        return self.model.warp_mm * np.sqrt(2.0 / len(self.phases)) * modes.sum(axis=1)

    def as_built(self, vertices: np.ndarray, normals: np.ndarray, centre: np.ndarray) -> np.ndarray:
        """(v, 3) the vertices of the part as built, in its nominal frame: scaled about
        `centre` and displaced along their (v, 3) unit normals by the warp."""
        out = vertices + self.warp_mm(vertices)[:, None] * normals
        if self.scale != 0.0:
            out = centre + (out - centre) * (1.0 + self.scale)
        return out

    def T_part_placed(self, centre: np.ndarray) -> np.ndarray:
        """(4, 4) where the part really sits, in its nominal frame: rotated about `centre`
        by the rotation error, then shifted by the translation error."""
        T = np.eye(4)
        if not (self.place_rotvec_rad.any() or self.place_t_mm.any()):
            return T
        R = rotation_matrix(self.place_rotvec_rad)
        T[:3, :3] = R
        T[:3, 3] = centre - R @ centre + self.place_t_mm
        return T

    def path_poses(self, poses: np.ndarray) -> np.ndarray:
        """(n, 4, 4) the poses the robot really flies: each nominal pose moved by its own
        translation and rotation error (about the sensor's origin, in the part frame)."""
        if self.model.path_mm.size == 0.0 and self.model.path_deg.size == 0.0:
            return poses
        rng = np.random.default_rng(self.path_seed)
        n = len(poses)
        dt = self.model.path_mm.draw(rng, (n, 3))
        dR = rotation_matrix(np.radians(self.model.path_deg.draw(rng, (n, 3))))
        out = poses.copy()
        out[:, :3, :3] = dR @ poses[:, :3, :3]
        out[:, :3, 3] += dt
        return out
