"""Colour consistency of a fitted pose with the segmented glove (core/tracking/evidence.py) and
the visible patch areas it rests on (PatchSurface.visible_patches)."""
from __future__ import annotations

import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.synthetic.frames import Synthesizer, render_frame
from colorglove_ros.core.synthetic.sequences import generate_sequence
from colorglove_ros.core.tracking.evidence import glove_evidence
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.core.tracking.patch_surface import PatchSurface
from colorglove_ros.core.tracking.types import Blobs

YELLOW, LIME = 4, 10
SETTINGS = dict(min_patch_px=30.0, near_patch_sizes=1.5, min_blob_share=0.1)


@pytest.fixture(scope='module')
def scene():
    synth = Synthesizer()
    cam = load_calibration(CONFIG_DIR / 'calibration.yaml').cameras[0]
    surface = PatchSurface(FastKinematics(synth.model), synth.mesh, synth.glove.face_patch)
    yield synth, cam, surface
    synth.release()


def _poses(scene, n: int = 5) -> np.ndarray:
    synth, cam, _ = scene
    return generate_sequence(11, n, camera=cam, model=synth.model)


def _seen_blobs(surface: PatchSurface, patch_color: np.ndarray, q: np.ndarray, cam,
                drop: tuple[int, ...] = ()) -> Blobs:
    """One blob per visible patch, where and as large as the pose shows it, without the
    colours ``drop``."""
    area, centroid = surface.visible_patches(q, cam)
    keep = np.flatnonzero((area > 0) & ~np.isin(patch_color, drop))
    return Blobs(patch_color[keep], centroid[keep], area[keep])


def test_visible_patches_match_the_rendered_glove(scene) -> None:
    synth, cam, surface = scene
    for q in _poses(scene):
        frame = render_frame(q, cam, np.random.default_rng(0), synthesizer=synth)
        ids = frame.patch_ids.astype(np.int64) - 1
        rendered = np.bincount(ids[ids >= 0], minlength=surface.num_patches)
        area, centroid = surface.visible_patches(q, cam)
        assert area.sum() == pytest.approx(rendered.sum(), rel=0.2)
        big = rendered >= 300
        np.testing.assert_allclose(area[big], rendered[big], rtol=0.5)
        truth = np.array([np.argwhere(ids == p)[:, ::-1].mean(axis=0)
                          for p in np.flatnonzero(big)])
        assert np.median(np.linalg.norm(centroid[big] - truth, axis=1)) < 3.0
        assert np.all(np.isnan(centroid[area == 0]))


def test_a_pose_that_shows_what_was_seen_misses_nothing(scene) -> None:
    synth, cam, surface = scene
    color = np.asarray(synth.glove.patch_color)
    for q in _poses(scene):
        seen = glove_evidence(surface, color, q, cam, _seen_blobs(surface, color, q, cam),
                              **SETTINGS)
        assert seen.missing_share == 0.0 and seen.missing_colors == ()
        assert seen.shown_px > 1000


def test_colours_the_image_lacks_are_missing_glove(scene) -> None:
    synth, cam, surface = scene
    color = np.asarray(synth.glove.patch_color)
    q = _poses(scene)[0]
    area, _ = surface.visible_patches(q, cam)
    counted = area >= SETTINGS['min_patch_px']
    lost = counted & np.isin(color, (YELLOW, LIME))
    assert lost.any()
    seen = glove_evidence(surface, color, q, cam,
                          _seen_blobs(surface, color, q, cam, (YELLOW, LIME)), **SETTINGS)
    assert seen.missing_share == pytest.approx(area[lost].sum() / area[counted].sum())
    assert set(seen.missing_colors) == set(color[lost].tolist())


def test_blobs_far_away_or_tiny_do_not_count(scene) -> None:
    synth, cam, surface = scene
    color = np.asarray(synth.glove.patch_color)
    q = _poses(scene)[0]
    blobs = _seen_blobs(surface, color, q, cam)
    far = Blobs(blobs.color, blobs.centroid_px + 200.0, blobs.pixel_count)
    assert glove_evidence(surface, color, q, cam, far, **SETTINGS).missing_share == 1.0
    specks = Blobs(blobs.color, blobs.centroid_px, np.ones(len(blobs)))
    assert glove_evidence(surface, color, q, cam, specks, **SETTINGS).missing_share == 1.0
    assert glove_evidence(surface, color, q, cam, Blobs.empty(), **SETTINGS
                          ).missing_share == 1.0


def test_a_pose_showing_no_glove_has_no_share(scene) -> None:
    synth, cam, surface = scene
    q = _poses(scene)[0].copy()
    q[2] = -q[2]                           # behind the camera
    seen = glove_evidence(surface, np.asarray(synth.glove.patch_color), q, cam, Blobs.empty(),
                          **SETTINGS)
    assert np.isnan(seen.missing_share) and seen.shown_px == 0.0


def test_of_a_cut_hand_only_the_glove_inside_the_image_counts(scene) -> None:
    synth, cam, surface = scene
    color = np.asarray(synth.glove.patch_color)
    q = _poses(scene)[0].copy()
    area, centroid = surface.visible_patches(q, cam)
    shown = np.flatnonzero(area >= SETTINGS['min_patch_px'])
    # the hand moved so that the border runs through the middle of its patches' rows
    cut_row = float(np.median(centroid[shown, 1]))
    q[1] += (cam.height - cut_row) * q[2] / cam.fy
    area, centroid = surface.visible_patches(q, cam)
    inside = (area > 0) & (centroid[:, 1] < cam.height)
    seen = Blobs(color[inside], centroid[inside], area[inside])       # what the image holds
    cut = glove_evidence(surface, color, q, cam, seen, inside_image_only=True, **SETTINGS)
    uncut = glove_evidence(surface, color, q, cam, seen, **SETTINGS)
    assert cut.missing_share == 0.0
    # an uncut hand's fit that puts glove beyond the border is refused as before
    assert uncut.missing_share > 0.3
