"""Held-out 'test' frames with ground-truth labels for the segmentation evaluation, from the
rendered glove (``frames.py``) or the 2-D stand-in glove (``blob_glove.py``), plus frames with
no glove."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from colorglove_ros.core.synthetic.blob_glove import render_blob_frame, sample_blob_conditions
from colorglove_ros.core.synthetic.conditions import sample_conditions
from colorglove_ros.core.synthetic.frames import default_camera, render_frame, sample_pose

__all__ = ['held_out_frames']


def held_out_frames(source: str, count: int, seed: int, empty: int = 0,
                clutter_near_hand: bool = False
                ) -> list[tuple[np.ndarray, np.ndarray, dict[str, float]]]:
    """``count`` held-out 'test' frames with ground truth labels, plus ``empty`` frames with
    no glove (hand moved out of view): (image, labels, imaging conditions) each. With
    ``clutter_near_hand`` ('synth' only) the glove-like background distractors may lie next to
    or behind the hand, as in the tracking sequences, instead of away from it."""
    rng = np.random.default_rng(seed)
    frames: list[tuple[np.ndarray, np.ndarray, dict[str, float]]] = []
    if source == 'blobs':
        if clutter_near_hand:
            raise ValueError("clutter_near_hand needs source 'synth'")
        for i in range(count + empty):
            cond = sample_blob_conditions(rng, 'test')
            img, lab = render_blob_frame(rng, cond)
            if i >= count:
                img, lab = render_blob_frame(rng, sample_blob_conditions(rng, 'test'))
                keep = lab == 0
                img = np.where(keep[..., None], img, np.uint8(90))
                lab = np.zeros_like(lab)
            frames.append((img, lab, {'gain': cond.light, 'noise': cond.noise_sigma / 255.0}))
        return frames
    if source != 'synth':
        raise ValueError(f"source must be 'synth' or 'blobs', got {source!r}")
    camera = default_camera()
    for i in range(count + empty):
        q = sample_pose(rng, camera)
        if i >= count:
            q[0] += 10.0  # far outside the field of view: background only
        cond = sample_conditions(rng, 'test')
        if clutter_near_hand:
            cond = replace(cond, distractors_avoid_hand=False)
        f = render_frame(q, camera, rng, cond)
        frames.append((f.image_rgb, f.labels, {
            'blur_px': cond.blur_px, 'jpeg_quality': cond.jpeg_quality, 'gain': cond.gain,
            'temperature_k': cond.color_temperature_k, 'noise': cond.noise_sigma}))
    return frames
