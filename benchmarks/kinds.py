"""Parts of kinds the shared set lacks, made here for the view benchmarks (not shipped: the
package's parts are the door, the drone and the training piece). Each is a closed solid in
mm, resting on z = 0:

- `heightfield`: a sin·cos heightfield (±15 mm over 240 x 200 mm) on a 40 mm base;
- `housing`: a cast gearbox housing, simplified: a 300 x 200 mm flange plate, a rounded body
  on it with a bowl-shaped cavity 70 mm deep, ribs standing on the flange against the body,
  bolt bosses at the flange's corners.

- `wavy`: a doubly curved panel, 700 x 260 mm: two long waves (±25 mm, 350 mm apart)
  along it and a gentle trough across it (9 mm deep at the edges), on a 40 mm base; a kind
  the policies never trained on (their strips are flat across, at most a 10° cross slope).

These three are heightfields over a grid (vertical walls, no overhangs), so they are
watertight by construction (`scanplan.world.parts.heightfield.heightfield_solid`). One more has
overhangs, made of boxes (closed solids that touch, not merged: rays and the body check see
the same surface):

- `slotted`: a slotted holder: a 240 x 160 x 30 mm block with two T-rails along it, each a
  20 mm web under a 40 mm wide cap, so the webs' walls lie 10 mm under the caps' edges.
"""

from __future__ import annotations

import numpy as np
import trimesh

from scanplan.world.part import Part, part_from_mesh
from scanplan.world.parts.heightfield import heightfield_solid


def heightfield() -> Part:
    xs = np.linspace(0.0, 240.0, 161)
    ys = np.linspace(0.0, 200.0, 135)
    gx, gy = np.meshgrid(xs, ys)
    z = 40.0 + 15.0 * np.sin(2 * np.pi * gx / 120.0) * np.cos(2 * np.pi * gy / 100.0)
    return part_from_mesh(heightfield_solid(xs, ys, z), "heightfield")


def housing() -> Part:
    xs = np.linspace(0.0, 300.0, 241)
    ys = np.linspace(0.0, 200.0, 161)
    gx, gy = np.meshgrid(xs, ys)
    z = np.full(gx.shape, 15.0)  # the flange
    # The body: a rounded rectangle 220 x 140 mm, 110 mm high.
    u, v = (gx - 150.0) / 110.0, (gy - 100.0) / 70.0
    body = u**4 + v**4 <= 1.0
    z[body] = 110.0
    # The bowl: an ellipsoidal cavity 190 x 110 mm, 70 mm deep.
    r2 = ((gx - 150.0) / 95.0) ** 2 + ((gy - 100.0) / 55.0) ** 2
    bowl = r2 < 1.0
    z[bowl] = 110.0 - 70.0 * np.sqrt(1.0 - r2[bowl])
    # Ribs on the flange, 5 mm thick, against the body's long sides, 80 mm high.
    for x0 in (90.0, 150.0, 210.0):
        rib = (np.abs(gx - x0) <= 2.5) & ~body & (np.abs(gy - 100.0) < 95.0)
        z[rib] = np.maximum(z[rib], 80.0)
    # Bolt bosses at the corners: 24 mm across, 35 mm high.
    for cx in (20.0, 280.0):
        for cy in (20.0, 180.0):
            z[np.hypot(gx - cx, gy - cy) <= 12.0] = 35.0
    return part_from_mesh(heightfield_solid(xs, ys, z), "housing")


def wavy() -> Part:
    xs = np.linspace(0.0, 700.0, 351)
    ys = np.linspace(-130.0, 130.0, 53)
    gx, gy = np.meshgrid(xs, ys)
    z = 70.0 + 25.0 * np.sin(2 * np.pi * gx / 350.0) + 9.0 * (gy / 130.0) ** 2
    return part_from_mesh(heightfield_solid(xs, ys, z), "wavy")


def slotted() -> Part:
    boxes = [((120.0, 80.0, 15.0), (240.0, 160.0, 30.0))]  # the block: centre, extents
    for y in (45.0, 115.0):
        boxes.append(((120.0, y, 42.5), (240.0, 20.0, 25.0)))  # the web
        boxes.append(((120.0, y, 60.0), (240.0, 40.0, 10.0)))  # the cap over it
    meshes = []
    for centre, extents in boxes:
        box = trimesh.creation.box(extents=extents)
        box.apply_translation(centre)
        meshes.append(box)
    return part_from_mesh(trimesh.util.concatenate(meshes), "slotted")


KINDS = {"heightfield": heightfield, "housing": housing, "slotted": slotted, "wavy": wavy}
