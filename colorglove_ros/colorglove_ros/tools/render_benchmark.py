"""Measure the headless renderer: batched label renders/s (tiny and 640x480), shaded frames/s."""
from __future__ import annotations

import os
import time

import numpy as np

from colorglove_ros.core.camera import PinholeCamera
from colorglove_ros.core.evaluation.machine_speed import machine_speed_after, machine_speed_before
from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.hand.poses import pose_collection, sample_global_rotations
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.synthetic.mesh_images import decimate_hand_mesh, vertex_normals
from colorglove_ros.core.synthetic.render import Renderer
from colorglove_ros.tools._cli import tool_parser


def _poses(n: int, seed: int, depth: float) -> np.ndarray:
    model, _, _ = default_hand()
    rng = np.random.default_rng(seed)
    fingers = pose_collection(seed=seed, size=max(n, 200), model=model)[:n]
    Q = np.tile(model.rest_pose(), (n, 1))
    Q[:, 2] = depth
    Q[:, 3:6] = sample_global_rotations(rng, n)
    Q[:, 6:] = fingers
    return Q


def _label_rate(size: tuple[int, int], n: int, batch: int, seed: int,
                cell_m: float = 0.0) -> dict:
    model, mesh, glove = default_hand()
    w, h = size
    depth = 0.5
    f = min(w, h) * depth / 0.24          # a 24 cm hand-sized box fills the image
    cam = PinholeCamera(w, h, f, f, (w - 1) / 2, (h - 1) / 2)
    if (w, h) == (640, 480):
        cam = PinholeCamera(w, h, 600.0, 600.0, 319.5, 239.5)
    Q = _poses(n, seed, depth)
    Q[:, 1] = 0.0
    r = Renderer(w, h, max_batch=batch)
    use_mesh, use_patch = mesh, glove.face_patch
    if cell_m > 0:
        use_mesh, use_patch = decimate_hand_mesh(mesh, glove.face_patch, cell_m)
    t0 = time.perf_counter()
    verts = use_mesh.skin_batch(model, Q)
    skin_dt = time.perf_counter() - t0
    r.render_patch_ids(verts[:min(n, batch)], use_mesh.faces, use_patch, cam)   # warm-up
    t0 = time.perf_counter()
    ids = r.render_patch_ids(verts, use_mesh.faces, use_patch, cam)
    dt = time.perf_counter() - t0
    row = {'what': f'labels {w}x{h}' + (f' decimated {1000 * cell_m:g} mm' if cell_m else ''),
           'faces': use_mesh.num_faces, 'batch': r.max_batch, 'images': n, 'per_s': n / dt,
           'ms_each': 1000 * dt / n, 'with_skinning_per_s': n / (dt + skin_dt),
           'fg_fraction': float((ids > 0).mean())}
    if cell_m > 0:
        full = r.render_patch_ids(mesh.skin_batch(model, Q), mesh.faces, glove.face_patch, cam)
        fg = (full > 0) | (ids > 0)
        row['same_patch_fraction'] = float(np.mean(full[fg] == ids[fg]))
    r.release()
    return row


def _shaded_rate(n: int, seed: int, smooth: bool, supersample: int = 1) -> dict:
    model, mesh, glove = default_hand()
    cam = PinholeCamera(640, 480, 600.0, 600.0, 319.5, 239.5)
    Q = _poses(n, seed, 0.5)
    verts = mesh.skin_batch(model, Q)
    rgb = (glove.face_rgb / 255.0).astype(np.float32)
    r = Renderer(640, 480, supersample=supersample)
    r.render_shaded(verts[0], mesh.faces, rgb, cam, face_patch=glove.face_patch)
    t0 = time.perf_counter()
    for v in verts:
        normals = vertex_normals(v, mesh.faces) if smooth else None
        r.render_shaded(v, mesh.faces, rgb, cam, face_patch=glove.face_patch, normals=normals)
    dt = time.perf_counter() - t0
    r.release()
    what = f'shaded 640x480 {"smooth" if smooth else "flat"}' + (
        f' {supersample}x{supersample} samples' if supersample > 1 else '')
    return {'what': what, 'batch': 1,
            'faces': mesh.num_faces, 'images': n, 'per_s': n / dt, 'ms_each': 1000 * dt / n}


def main(argv: list[str] | None = None) -> int:
    """Print the render rates; ``--json PATH`` writes them too."""
    parser = tool_parser(__doc__)
    parser.add_argument('--images', type=int, default=1024, help='tiny label renders to time')
    parser.add_argument('--full-images', type=int, default=96,
                        help='640x480 label and shaded renders to time')
    parser.add_argument('--batch', type=int, default=256, help='poses per draw call')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    _, mesh, _ = default_hand()
    machine = machine_speed_before()
    rows = [
        _label_rate((40, 40), args.images, args.batch, args.seed),
        _label_rate((96, 96), args.images, args.batch, args.seed),
        _label_rate((128, 128), args.images, args.batch, args.seed),
        _label_rate((96, 96), args.images, args.batch, args.seed, cell_m=0.004),
        _label_rate((128, 128), args.images, args.batch, args.seed, cell_m=0.004),
        _label_rate((640, 480), args.full_images, args.batch, args.seed),
        _shaded_rate(args.full_images, args.seed, smooth=False),
        _shaded_rate(args.full_images, args.seed, smooth=True),
        _shaded_rate(args.full_images, args.seed, smooth=True, supersample=2),
    ]
    print_table(rows, title=f'render benchmark (mesh: {mesh.num_vertices} vertices, '
                            f'{mesh.num_faces} faces; {os.cpu_count()} CPUs)')
    machine_speed_after(machine)
    if args.json:
        write_json(args.json, {'machine_speed': machine, 'mesh_vertices': mesh.num_vertices,
                               'mesh_faces': mesh.num_faces, 'rows': rows})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
