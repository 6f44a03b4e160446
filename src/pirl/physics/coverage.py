"""Coverage from a continuous pose, with the grid's footprint geometry.

The grid evaluates its footprint models (:mod:`pirl.world.footprint`) at a cell centre with a
level camera. A flying drone is between cells, and its body tilts the camera. This module
evaluates the same models from a continuous pose, reusing the grid's compiled geometry (the
frustum's corner rays, the point-in-polygon test, the occlusion test):

- ``paper``: the square of side ``2h + 1`` cells centred on the continuous (x, y) holds the
  cells whose centres lie in ``[x - h - 1/2, x + h + 1/2)``: exactly the grid's square around
  the nearest cell (halves rounded up). Tilt enters only through ``h`` (the model's rule), so
  the commanded tilt is used and the attitude does not matter, as in the paper's model.
- ``frustum``: the pinhole camera at the continuous position and height, pointed by the
  *effective* tilt and pan of its optical axis once the body's roll, pitch and yaw are applied
  to the gimbal angles (:func:`view_angles`). The image's roll about the optical axis is
  ignored (the frustum model has no such angle); it is small at the drone's lean angles.

At a cell centre with a level body both give exactly the grid's footprint (tested).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from pirl.world.footprint import (
    NO_GROUND,
    PAPER,
    CameraPose,
    footprint_cells,
    frustum_corners,
    frustum_over_ground,
    frustum_scan,
)


@numba.njit(cache=True)
def footprint_cells_pose(lens, pose, obstacles, occluding, ground, out):
    """Ground cells seen from a continuous :class:`~pirl.world.footprint.CameraPose`, written
    as rows (i, j) of ``out``; the count.

    ``pose.x, pose.y`` are in cell units (cell (i, j) is centred at (i, j)); ``pose.z`` is the
    height above the ground in cell units minus one (the grid's level convention, so level k
    is ``z = k``); tilt and pan are degrees (floats); ``obstacles`` in the same units;
    ``occluding`` the world's voxels (used where there are no spheres); ``ground`` a site's
    terrain in cell units (``NO_GROUND`` on flat ground), over which the frustum is projected
    on each cell's own ground and ``pose.z`` is the height above the ground under the camera.
    """
    if lens.model == PAPER:
        cell = CameraPose(
            int(math.floor(pose.x + 0.5)), int(math.floor(pose.y + 0.5)), 0,
            int(math.floor(pose.tilt + 0.5)), 0, pose.zoom10,
        )  # fmt: skip
        return footprint_cells(lens, cell, obstacles, occluding, NO_GROUND, out)
    if ground.shape[0] > 0:
        return frustum_over_ground(lens, pose, occluding, ground, out)
    poly = np.empty((4, 2))
    frustum_corners(lens, pose, poly)
    return frustum_scan(lens, pose, poly, obstacles, occluding, out)


def body_rotation(rpy: np.ndarray) -> np.ndarray:
    """Rotation body -> world for (roll, pitch, yaw) radians: Rz(yaw) @ Ry(pitch) @ Rx(roll).

    The convention of PyBullet's ``getEulerFromQuaternion`` and of Webots' inertial unit.
    """
    roll, pitch, yaw = (float(a) for a in rpy)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def view_angles(tilt: float, pan: float, rpy: np.ndarray, stabilized: bool) -> tuple[float, float]:
    """Effective (tilt, pan) in degrees of a gimbal camera on a tilted body.

    The gimbal's yaw axis is driven to the commanded world-frame ``pan`` (it compensates the
    body's heading); its pitch axis holds ``tilt`` below the body's horizontal plane, so body
    roll and pitch tilt the view unless the gimbal is ``stabilized`` (3-axis). Pan is read off
    the camera's right axis and tilt measured towards that heading, so a camera looking
    straight down keeps a well-defined footprint orientation, and one pitched past the nadir
    gets a tilt above 90 degrees.
    """
    if stabilized:
        return float(tilt), float(pan)
    t = math.radians(tilt)
    rel = math.radians(pan) - float(rpy[2])
    forward = np.array([math.cos(t) * math.cos(rel), math.cos(t) * math.sin(rel), -math.sin(t)])
    right = np.array([math.sin(rel), -math.cos(rel), 0.0])
    rot = body_rotation(rpy)
    f = rot @ forward
    r = rot @ right
    p_eff = math.atan2(r[0], -r[1])
    t_eff = math.atan2(-f[2], f[0] * math.cos(p_eff) + f[1] * math.sin(p_eff))
    return math.degrees(t_eff), math.degrees(p_eff)


__all__ = ["body_rotation", "footprint_cells_pose", "view_angles"]
