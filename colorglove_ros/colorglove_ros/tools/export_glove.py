"""Write the colour-glove mesh (PLY and GLB) and a picture of it from several views."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from colorglove_ros.core.conventions import DEFAULT_HAND_LENGTH_M, NUM_PATCHES
from colorglove_ros.core.geometry import rotvec_to_matrix
from colorglove_ros.core.hand.glove import GLOVE_COLOR_NAMES, Glove, default_hand, export_glove_mesh
from colorglove_ros.core.hand.handedness import HANDS, hand_faces, hand_vertices
from colorglove_ros.core.hand.mesh import HandMesh
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.poses import NAMED_SHAPES, full_pose
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.tools._cli import tool_parser

__all__ = ['main', 'draw_glove']

# (title, view rotation vector applied to the hand-frame mesh, finger shape)
_VIEWS = (
    ('palm (camera view)', (0.0, 0.0, 0.0), 'flat'),
    ('back', (0.0, np.pi, 0.0), 'flat'),
    ('thumb side', (0.0, -np.pi / 2, 0.0), 'flat'),
    ('three-quarter', (0.5, -0.7, 0.0), 'spread'),
    ('fist', (0.0, 0.0, 0.0), 'fist'),
    ('point, 3/4', (0.3, 0.6, 0.0), 'point'),
)


def draw_glove(ax, model: HandModel, mesh: HandMesh, glove: Glove, q: np.ndarray,
               view_rotvec: np.ndarray, title: str = '', hand: str = 'right') -> None:
    """Painter's-algorithm orthographic drawing of the ``hand``'s glove on a matplotlib axis,
    as the camera would see it (x right, y down) after rotating the hand by ``view_rotvec``
    (a left hand's view is the mirror image of the right hand's)."""
    from matplotlib.collections import PolyCollection

    q = q.copy()
    q[:3] = 0.0
    view = np.asarray(view_rotvec, float)
    if hand != 'right':   # the mirrored view of the mirror-image hand: the mirror picture
        view = view * [1.0, -1.0, -1.0]
    v = hand_vertices(mesh, model, q, hand) @ rotvec_to_matrix(view).T
    tri = v[hand_faces(mesh.faces, hand)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-18
    visible = normal[:, 2] < 0.0  # facing the viewer (camera looks along +z)
    order = np.argsort(-tri[:, :, 2].mean(1))
    order = order[visible[order]]
    light = np.array([0.3, -0.4, -1.0]) / np.linalg.norm([0.3, -0.4, -1.0])
    shade = 0.45 + 0.55 * np.clip(normal[order] @ light, 0.0, 1.0)
    colors = glove.face_rgb[order] / 255.0 * shade[:, None]
    polys = tri[order][:, :, :2] * np.array([1.0, -1.0])  # image y down -> plot y up
    ax.add_collection(PolyCollection(polys, facecolors=colors, edgecolors='none'))
    lo, hi = polys.reshape(-1, 2).min(0), polys.reshape(-1, 2).max(0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2 * 1.08
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_aspect('equal')
    ax.axis('off')
    ax.set_title(title, fontsize=9)


def main(argv: list[str] | None = None) -> int:
    """Export data/glove/glove.ply, glove.glb and glove.png (``--hand left``: left_glove.*,
    the mirror-image glove a left hand wears)."""
    parser = tool_parser(__doc__)
    parser.add_argument('--out', type=Path, default=Path('data/glove'), help='output folder')
    parser.add_argument('--hand-length', type=float, default=DEFAULT_HAND_LENGTH_M,
                        help='wrist to middle tip, m')
    parser.add_argument('--seed', type=int, default=0, help='glove pattern seed')
    parser.add_argument('--hand', choices=HANDS, default='right',
                        help="which hand's glove: 'left' is the mirror image of the right one")
    parser.add_argument('--shapes', action='store_true',
                        help='also draw every named hand shape into shapes.png')
    args = parser.parse_args(argv)

    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    model, mesh, glove = default_hand(args.hand_length, args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    stem = 'glove' if args.hand == 'right' else f'{args.hand}_glove'
    ply = export_glove_mesh(mesh, glove, model, args.out / f'{stem}.ply', hand=args.hand)
    glb = export_glove_mesh(mesh, glove, model, args.out / f'{stem}.glb', hand=args.hand)
    fig, axes = plt.subplots(2, 3, figsize=(12, 8.5))
    for ax, (title, rv, shape) in zip(axes.ravel(), _VIEWS, strict=True):
        draw_glove(ax, model, mesh, glove, full_pose(model, NAMED_SHAPES[shape]),
                   np.array(rv), title, args.hand)
    fig.suptitle(f'colour glove ({args.hand} hand): {NUM_PATCHES} patches, seed {args.seed}, '
                 f'hand length {args.hand_length:.3f} m')
    fig.tight_layout()
    png = args.out / f'{stem}.png'
    fig.savefig(png, dpi=110)
    plt.close(fig)

    if args.shapes:
        names = list(NAMED_SHAPES)
        cols = 8
        rows_n = (len(names) + cols - 1) // cols
        fig, axes = plt.subplots(rows_n, cols, figsize=(2.0 * cols, 2.3 * rows_n))
        for ax in axes.ravel():
            ax.axis('off')
        for ax, name in zip(axes.ravel(), names, strict=False):
            draw_glove(ax, model, mesh, glove, full_pose(model, NAMED_SHAPES[name]),
                       np.array([0.0, 0.35, 0.0]), name)
        fig.tight_layout()
        fig.savefig(args.out / 'shapes.png', dpi=80)
        plt.close(fig)
        print(f'wrote {args.out / "shapes.png"}')

    area = np.bincount(glove.face_patch, weights=mesh.to_trimesh(model).area_faces,
                       minlength=NUM_PATCHES)
    rows = [{'patch': p, 'colour': GLOVE_COLOR_NAMES[int(glove.patch_color[p]) - 1],
             'label': int(glove.patch_color[p]),
             'link': model.link_names[int(mesh.face_link[glove.seed_faces[p]])],
             'faces': int(np.sum(glove.face_patch == p)), 'area_cm2': float(area[p] * 1e4)}
            for p in range(NUM_PATCHES)]
    print_table(rows, title=f'glove: {mesh.num_faces} faces, {mesh.num_vertices} vertices')
    print(f'wrote {ply}, {glb}, {png}')
    if args.json is not None:
        write_json(args.json, {'faces': mesh.num_faces, 'vertices': mesh.num_vertices,
                               'patches': rows})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
