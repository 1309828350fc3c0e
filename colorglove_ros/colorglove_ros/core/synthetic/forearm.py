"""The forearm mesh drawn with a synthetic hand: the gloved hand's sleeve (``frames.py``) and
other people's bare arms in the background (``people.py``)."""
from __future__ import annotations

import numpy as np

from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M
from colorglove_ros.core.hand.model import HandModel

__all__ = ['FOREARM_LENGTH_M', 'forearm_mesh']

FOREARM_LENGTH_M = 0.50     # drawn length of a default-size hand's forearm (out of view)


def forearm_mesh(model: HandModel, length_m: float = FOREARM_LENGTH_M
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A closed elliptic frustum in the hand frame, along +y from the wrist, ``length_m`` long
    for a default-size hand (scaled with the hand), with outward counter-clockwise faces:
    vertices (V, 3) and faces (F, 3) int32."""
    s = model.hand_length_m / DEFAULT_HAND_LENGTH_M
    n = 20
    ang = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    rings = []
    for y, rx, rz in ((-0.004, 0.028, 0.0135), (length_m, 0.040, 0.032)):
        rings.append(np.stack([rx * s * np.cos(ang), np.full(n, y * s),
                               rz * s * np.sin(ang) - 0.001 * s], axis=1))
    verts = np.concatenate([*rings, [[0.0, -0.004 * s, -0.001 * s],
                                     [0.0, length_m * s, -0.001 * s]]])
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, j, n + j], [i, n + j, n + i]]
        faces += [[2 * n, j, i], [2 * n + 1, n + i, n + j]]
    verts, faces = np.asarray(verts), np.asarray(faces, dtype=np.int32)
    # orient outward: flip all faces if the signed volume is negative
    tri = verts[faces]
    vol = np.einsum('ij,ij->i', tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
    if vol < 0:
        faces = faces[:, ::-1].copy()
    return verts, faces
