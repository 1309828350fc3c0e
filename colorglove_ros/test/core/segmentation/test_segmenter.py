"""Tests for the glove segmenter, its no-hand handling and the calibration/eval tools."""
from __future__ import annotations

import inspect
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from segmentation_samples import blob_glove_calibration, printed_glove_calibration

from colorglove_ros.core.colorimetry import srgb_to_linear
from colorglove_ros.core.conventions import TINY_SIZE
from colorglove_ros.core.evaluation.machine_speed import MACHINE_SPEED_TITLE
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.segmentation.calibration_fit import (
    read_labelled_frames,
    render_training_frames,
    write_labelled_frames,
)
from colorglove_ros.core.segmentation.color_model import read_calibration_config
from colorglove_ros.core.segmentation.crop import crop_to_tiny
from colorglove_ros.core.segmentation.segmenter import (
    STAGES,
    STATUS_FRAGMENTED,
    STATUS_NO_GLOVE,
    STATUS_OK,
    STATUS_OUT_OF_FRAME,
    STATUS_TOO_SMALL,
    GloveSegmenter,
    SegmentationConfigError,
    SegmentationInputError,
    border_contact_px,
    keep_multicolor_components,
    load_segmenter,
    relabel_borders,
)
from colorglove_ros.core.synthetic.blob_glove import (
    BlobConditions,
    render_blob_frame,
    sample_blob_conditions,
)
from colorglove_ros.core.synthetic.held_out import held_out_frames
from colorglove_ros.core.validation import SEGMENTER_RULES
from colorglove_ros.tools import calibrate_colors, eval_segmentation
from colorglove_ros.tools.eval_segmentation import frame_metrics

VALID = {STATUS_OK, STATUS_NO_GLOVE, STATUS_TOO_SMALL, STATUS_OUT_OF_FRAME, STATUS_FRAGMENTED}


@pytest.fixture(scope='module')
def calibration():
    return blob_glove_calibration()


@pytest.fixture(scope='module')
def segmenter(calibration) -> GloveSegmenter:
    return GloveSegmenter(calibration)


def test_held_out_frames_crop_and_centroids(segmenter) -> None:
    rng = np.random.default_rng(5)
    ious, errs = [], []
    for _ in range(4):
        img, lab = render_blob_frame(rng, sample_blob_conditions(rng, 'train'))
        obs = segmenter.process(img)
        assert obs.hand_found and obs.status == STATUS_OK
        assert obs.tiny_labels.shape == (TINY_SIZE, TINY_SIZE)
        assert obs.tiny_labels.dtype == np.uint8
        assert (obs.image_width, obs.image_height) == (640, 480)
        assert set(obs.timings_ms) == {*STAGES, 'total'}
        assert obs.glove_pixel_count == pytest.approx(np.count_nonzero(lab), rel=0.25)
        m = frame_metrics(segmenter, img, lab, obs)
        ious.append(m['iou'])
        errs.append(m['centroid_err_px'])
        # The crop transform maps the tiny image back onto the glove.
        ty, tx = np.nonzero(obs.tiny_labels)
        back = obs.crop.to_full(np.array([tx.mean(), ty.mean()]))
        gy, gx = np.nonzero(lab)
        assert np.hypot(*(back - [gx.mean(), gy.mean()])) < 2.0 * obs.crop.scale
        assert all(b.pixel_count >= segmenter.min_blob_pixels for b in obs.blobs)
        assert {b.color_label for b in obs.blobs} <= set(np.unique(lab)) - {0}
    assert np.mean(ious) > 0.85
    assert np.nanmean(errs) < 3.0


def test_no_hand_frames_never_raise(segmenter) -> None:
    rng = np.random.default_rng(2)
    frames = [np.zeros((480, 640, 3), np.uint8), np.full((480, 640, 3), 255, np.uint8),
              rng.integers(0, 256, (480, 640, 3)).astype(np.uint8),
              np.zeros((1, 1, 3), np.uint8), np.zeros((7, 5, 3), np.uint8),
              rng.integers(0, 256, (3, 900, 3)).astype(np.uint8)]
    img, lab = render_blob_frame(rng, sample_blob_conditions(rng, 'test'))
    frames.append(np.where(lab[..., None] > 0, np.uint8(120), img))  # glove painted out
    for f in frames:
        obs = segmenter.process(f)
        assert not obs.hand_found
        assert obs.status in VALID - {STATUS_OK}
    assert segmenter.process(frames[0]).status == STATUS_NO_GLOVE


def test_strided_and_readonly_frames(segmenter) -> None:
    rng = np.random.default_rng(9)
    img, _ = render_blob_frame(rng, sample_blob_conditions(rng, 'train'))
    ref = segmenter.process(img)
    ro = img.copy()
    ro.setflags(write=False)
    for view in (ro, np.asfortranarray(img), img[:, :, ::-1][:, :, ::-1]):
        obs = segmenter.process(view)
        assert obs.hand_found
        np.testing.assert_array_equal(obs.tiny_labels, ref.tiny_labels)
    assert segmenter.process(img[::-1, ::-1]).hand_found  # rotated 180 degrees


def test_single_colour_clutter_is_not_a_hand(segmenter) -> None:
    img = np.full((480, 640, 3), 110, np.uint8)
    img[100:300, 200:400] = GLOVE_PALETTE_RGB[2]  # a big blue box
    img[350:420, 50:120] = GLOVE_PALETTE_RGB[0]   # a separate red one
    obs = segmenter.process(img)
    assert not obs.hand_found and obs.status == STATUS_NO_GLOVE


def test_hand_mostly_out_of_frame(segmenter) -> None:
    rng = np.random.default_rng(8)
    img, lab = render_blob_frame(rng, BlobConditions(1.0, (1.0, 1.0, 1.0), 2.0, 0, False, 1.5))
    ys, xs = np.nonzero(lab)
    assert segmenter.process(img).hand_found
    # shift the glove so only a sliver stays inside the right edge
    shift = int(640 - xs.min() - 0.25 * (xs.max() - xs.min()))
    moved = np.full_like(img, 110)
    moved[:, shift:] = img[:, :640 - shift]
    obs = segmenter.process(moved)
    assert not obs.hand_found
    assert obs.status in (STATUS_OUT_OF_FRAME, STATUS_TOO_SMALL, STATUS_NO_GLOVE)


@pytest.mark.parametrize('side', ['left', 'right', 'top', 'bottom'])
def test_a_glove_reaching_the_image_border_is_marked_cut(segmenter, side) -> None:
    rng = np.random.default_rng(8)
    img, lab = render_blob_frame(rng, BlobConditions(1.0, (1.0, 1.0, 1.0), 2.0, 0, False, 1.5))
    whole = segmenter.process(img)
    assert whole.hand_found and not whole.cut_by_border
    ys, xs = np.nonzero(lab)
    # move the glove so a fifth of its width or height lies beyond one border
    dx = {'left': -int(xs.min() + 0.2 * np.ptp(xs)), 'right': int(639 - xs.max() + 0.2 * np.ptp(xs))
          }.get(side, 0)
    dy = {'top': -int(ys.min() + 0.2 * np.ptp(ys)), 'bottom': int(479 - ys.max() + 0.2 * np.ptp(ys))
          }.get(side, 0)
    moved = cv2.warpAffine(img, np.float32([[1, 0, dx], [0, 1, dy]]), (640, 480),
                           borderMode=cv2.BORDER_REPLICATE)
    obs = segmenter.process(moved)
    assert obs.glove_pixel_count > 0 and obs.cut_by_border


def test_only_the_hands_window_counts_towards_border_contact() -> None:
    """Glove-coloured clutter running off the image beside the hand does not cut the hand;
    the hand's own crop window reaching the border does."""
    labels = np.zeros((40, 60), np.uint8)
    labels[:, 0] = 2                      # clutter along the left border, rows 0..39
    labels[10:20, 30:50] = 5              # the hand, away from it
    roi = (0, 120, 100, 180)              # the region starts at the image's left border
    assert border_contact_px(labels, roi, 2, 640, 480) == 80
    assert border_contact_px(labels, roi, 2, 640, 480, (25, 55, 5, 25)) == 0
    assert border_contact_px(labels, roi, 2, 640, 480, (0, 55, 5, 25)) == 40


def _noise_patch_frames(seed: int, count: int) -> list[np.ndarray]:
    """Black frames with a hand-sized square of uniform random colours (issue 16)."""
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(count):
        frame = np.zeros((480, 640, 3), np.uint8)
        side = int(rng.integers(120, 220))
        y, x = rng.integers(0, 480 - side), rng.integers(0, 640 - side)
        frame[y:y + side, x:x + side] = rng.integers(0, 256, (side, side, 3))
        frames.append(frame)
    return frames


@pytest.fixture(scope='module')
def glove_calibration():
    """A quick colour calibration on rendered frames of the printed glove."""
    return printed_glove_calibration()


def test_noise_patches_are_fragmented_not_a_hand(glove_calibration) -> None:
    """Random-colour patches give glove-coloured specks, not solid patches: no hand, status
    'fragmented'; without the blob-share check they pass as a hand. Rendered glove frames
    are never fragmented."""
    frames = _noise_patch_frames(3, 6)
    segmenter = GloveSegmenter(glove_calibration)
    assert not any(segmenter.process(f).hand_found for f in frames)
    # the blob-share check alone (without finding the glove by its colour diversity and the
    # scene's own colours) calls them fragmented ...
    no_detection = dict(diversity_window=0, scene_colour_min_share=0.0)
    blob_share_only = GloveSegmenter(glove_calibration, **no_detection)
    gated = [blob_share_only.process(f) for f in frames]
    assert all(o.status == STATUS_FRAGMENTED for o in gated), [o.status for o in gated]
    # ... and with neither they pass as a hand
    ungated = GloveSegmenter(glove_calibration, min_blob_share=0.0, **no_detection)
    assert all(ungated.process(f).hand_found for f in frames)
    for image, _ in render_training_frames(4, 5, 'test'):
        assert segmenter.process(image).status == STATUS_OK


@pytest.mark.parametrize('bad', [
    np.zeros((10, 10, 3), np.float32), np.zeros((10, 10), np.uint8),
    np.zeros((10, 10, 4), np.uint8), np.zeros((0, 0, 3), np.uint8), [[0, 0, 0]],
])
def test_bad_input_raises_typed_error(segmenter, bad) -> None:
    with pytest.raises(SegmentationInputError):
        segmenter.process(bad)


def test_keep_multicolor_components() -> None:
    lab = np.zeros((40, 60), np.uint8)
    lab[5:15, 5:10], lab[5:15, 10:15], lab[5:15, 15:20] = 1, 2, 3   # three colours touching
    lab[25:35, 30:50] = 4                                             # one colour alone
    lab[25:35, 52:55] = 5
    out = keep_multicolor_components(lab, min_colors=3)
    np.testing.assert_array_equal(out[5:15, 5:20], lab[5:15, 5:20])
    assert not out[20:].any()


def test_keep_multicolor_components_counts_only_glove_pixels() -> None:
    lab = np.zeros((30, 30), np.uint8)
    lab[2:12, 2:12] = 1                 # a big one-colour component
    lab[20:22, 20] = 2                  # a 2-pixel speck
    out = keep_multicolor_components(lab, min_colors=1, min_pixels=4)
    np.testing.assert_array_equal(out[:15], lab[:15])
    assert not out[15:].any()
    # a boolean mask works the same way (one colour: True)
    mask_out = keep_multicolor_components(lab > 0, min_colors=1, min_pixels=4)
    np.testing.assert_array_equal(mask_out, out > 0)


def test_keep_multicolor_components_reattaches_cut_off_pieces() -> None:
    """A one-colour piece a few pixels from the kept glove (a fingertip cut off by a thin line
    of unclassified pixels) is kept with ``reattach_radius``; one far away, or one larger than
    ``reattach_max_share`` of the glove, is still dropped."""
    lab = np.zeros((40, 80), np.uint8)
    lab[5:35, 5:10], lab[5:35, 10:15], lab[5:35, 15:20] = 1, 2, 3   # the glove, 450 px
    lab[5:15, 22:26] = 4                                              # 2 px gap: a fingertip
    lab[25:35, 60:70] = 4                                             # far away: clutter
    glove_and_tip = (slice(None), slice(0, 30))
    plain = keep_multicolor_components(lab, min_colors=3)
    assert not plain[5:15, 22:26].any()
    out = keep_multicolor_components(lab, min_colors=3, reattach_radius=3)
    np.testing.assert_array_equal(out[glove_and_tip], lab[glove_and_tip])
    assert not out[:, 30:].any()
    # the gap is wider than a radius of 2 reaches
    assert not keep_multicolor_components(lab, min_colors=3, reattach_radius=2)[:, 22:].any()
    # a piece holding more than reattach_max_share (0.2) of the glove's pixels stays dropped
    lab[5:15, 22:26] = 0
    lab[5:20, 22:40] = 4                                              # 270 px
    assert not keep_multicolor_components(lab, min_colors=3, reattach_radius=3)[:, 22:].any()
    grown = keep_multicolor_components(lab, min_colors=3, reattach_radius=3,
                                       reattach_max_share=0.7)
    np.testing.assert_array_equal(grown[5:20, 22:40], lab[5:20, 22:40])
    with pytest.raises(SegmentationConfigError):
        keep_multicolor_components(lab, reattach_radius=-1)


def test_segmenter_keeps_cut_off_fingertip_drops_far_clutter(calibration) -> None:
    """In a frame, a glove-coloured square 1 px from the glove is kept as part of the hand
    (with the default ``reattach_radius``) and the same square far away is not."""
    rng = np.random.default_rng(8)
    img, lab = render_blob_frame(rng, BlobConditions(1.0, (1.0, 1.0, 1.0), 0.0, 2, False, 1.0))
    ys, xs = np.nonzero(lab)
    right = int(xs.max())
    row = int(np.median(ys[xs >= right - 2]))
    color = np.asarray(GLOVE_PALETTE_RGB[3], np.uint8)
    near = (slice(row - 4, row + 5), slice(right + 2, right + 11))   # a 1 px gap
    far_col = right + 120 if right + 140 < img.shape[1] else int(xs.min()) - 130
    far = (slice(row - 4, row + 5), slice(far_col, far_col + 9))
    img = img.copy()
    img[near] = color
    img[far] = color
    results = {radius: GloveSegmenter(calibration, max_roi_cells=400,
                                      reattach_radius=radius).process(img, keep_labels=True)
               for radius in (0, 3)}
    for obs in results.values():
        assert obs.hand_found
        assert not obs.label_image[far].any()
    assert not results[0].label_image[near].any()
    assert np.count_nonzero(results[3].label_image[near] == 4) > 0.8 * 81
    with pytest.raises(SegmentationConfigError, match='reattach_radius'):
        GloveSegmenter(calibration, reattach_radius=-1)


def test_every_setting_is_checked_however_the_segmenter_is_built(calibration) -> None:
    """The keyword settings are exactly the validation rules' keys, so each is checked and
    kept; a segmenter built in code refuses what a colour config would."""
    keywords = set(inspect.signature(GloveSegmenter).parameters) - {'calibration', 'source'}
    assert keywords == set(SEGMENTER_RULES)
    segmenter = GloveSegmenter(calibration, border_distances=[3, 5], roi_margin=2)
    assert segmenter.border_distances == (3, 5) and isinstance(segmenter.roi_margin, float)
    for key, value, message in [('median_size', 4, 'median_size must be odd'),
                                ('bilateral_sigma_space', 0.0, 'must be > 0'),
                                ('coarse_factor', 0, 'coarse_factor must be >= 1'),
                                ('roi_margin', float('nan'), 'roi_margin must be finite')]:
        with pytest.raises(SegmentationConfigError, match=f'GloveSegmenter: .*{message}'):
            GloveSegmenter(calibration, **{key: value})


def _mixed_edge(width: int = 40, height: int = 12, edge: float = 19.5, blur: float = 4.0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A red | yellow edge at x = ``edge`` blurred over ``blur`` pixels (mixed in linear
    light, like motion blur) -> (image, true labels, red share of each column)."""
    red = srgb_to_linear(GLOVE_PALETTE_RGB[0] / 255.0)
    yellow = srgb_to_linear(GLOVE_PALETTE_RGB[3] / 255.0)
    x = np.arange(width, dtype=float)
    share = np.clip((edge + 0.5 * blur - 0.5 - x) / blur + 0.5 / blur, 0.0, 1.0)
    lin = share[:, None] * red + (1.0 - share[:, None]) * yellow
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    image = np.broadcast_to(np.round(255 * srgb).astype(np.uint8), (height, width, 3)).copy()
    truth = np.broadcast_to(np.where(x < edge, 1, 4).astype(np.uint8), (height, width)).copy()
    return image, truth, share


def test_relabel_borders_gives_mixed_pixels_their_majority_colour() -> None:
    image, truth, share = _mixed_edge()
    band = np.flatnonzero((share > 0) & (share < 1))
    assert len(band) >= 3
    # The classifier put the mixed band into background and orange (red + yellow).
    labels = truth.copy()
    labels[:, band] = np.where(np.arange(len(band)) % 2, 7, 0)
    np.testing.assert_array_equal(relabel_borders(image, labels, passes=0), labels)
    out = relabel_borders(image, labels)
    np.testing.assert_array_equal(out, truth)
    # A 4-pixel band all in background: one pass fixes its outer pixels, the second the rest.
    image, truth, share = _mixed_edge(blur=5.0)
    labels = np.where((share > 0) & (share < 1), np.uint8(0), truth)
    assert np.mean(relabel_borders(image, labels, passes=1) == truth) < 1.0
    np.testing.assert_array_equal(relabel_borders(image, labels, passes=2), truth)
    # A 6-pixel band (strong blur) needs three passes, as the defaults and shipped settings do.
    image, truth, share = _mixed_edge(blur=6.0)
    labels = np.where((share > 0) & (share < 1), np.uint8(0), truth)
    assert np.mean(relabel_borders(image, labels, passes=2) == truth) < 1.0
    np.testing.assert_array_equal(relabel_borders(image, labels), truth)
    shipped = read_calibration_config('config/color_calibration.yaml')['segmenter']
    np.testing.assert_array_equal(relabel_borders(
        image, labels, shipped['border_passes'], tuple(shipped['border_distances'])), truth)


def test_relabel_borders_leaves_clean_regions_and_unknown_colours() -> None:
    rng = np.random.default_rng(3)
    image = np.zeros((30, 30, 3), np.uint8)
    labels = np.zeros((30, 30), np.uint8)
    image[:, 8:24] = GLOVE_PALETTE_RGB[2]
    labels[:, 8:24] = 3
    # sharp patches 5 pixels wide or more keep a sure pixel in reach of their edges: no change
    image[:, 13:18] = GLOVE_PALETTE_RGB[5]
    labels[:, 13:18] = 6
    np.testing.assert_array_equal(relabel_borders(image, labels), labels)
    # a sharp 3-pixel strip has no sure pixel in reach of its edges, but its colour is no mix
    # of its neighbours' colours: it stays (a mixed band of the same width does not)
    strip = np.zeros((20, 24), np.uint8)
    strip[:, 10:13] = 1
    strip_image = np.where(strip[..., None] > 0, GLOVE_PALETTE_RGB[1], GLOVE_PALETTE_RGB[0])
    strip_labels = np.where(strip > 0, 2, 1).astype(np.uint8)
    np.testing.assert_array_equal(relabel_borders(strip_image, strip_labels), strip_labels)
    assert not (relabel_borders(strip_image, strip_labels, min_residual=1e9)
                == 2).any()
    # no border at all: returned unchanged
    flat = np.full((8, 8), 2, np.uint8)
    np.testing.assert_array_equal(relabel_borders(rng.integers(0, 256, (8, 8, 3)).astype(
        np.uint8), flat), flat)
    # a lone speck with no sure pixel of its own takes its surroundings' label
    labels[5, 2] = 9
    assert relabel_borders(image, labels)[5, 2] == 0


def test_border_relabel_raises_pixel_accuracy_on_blurred_frames(calibration) -> None:
    """The held-out blob frames, motion-blurred: relabelling borders must help clearly."""
    rng = np.random.default_rng(17)
    kernel = np.zeros((5, 5), np.float32)
    kernel[2, :] = 1.0 / 5.0
    with_relabel = GloveSegmenter(calibration)
    without = GloveSegmenter(calibration, border_passes=0)
    gain = []
    for _ in range(3):
        img, lab = render_blob_frame(rng, sample_blob_conditions(rng, 'test'))
        img = cv2.filter2D(img, -1, kernel)
        g = lab > 0
        acc = [np.mean(seg.classify_full(img)[g] == lab[g]) for seg in (with_relabel, without)]
        gain.append(acc[0] - acc[1])
    assert np.mean(gain) > 0.01


def test_light_correction_beats_uncorrected_under_tinted_light(calibration) -> None:
    """Frames under strongly warm and cool lights (far outside the light colours the
    calibration was re-lit under): dividing out the estimated light colour must classify
    the glove clearly better, and change little under the calibration's own light."""
    rng = np.random.default_rng(23)
    corrected, plain = GloveSegmenter(calibration), GloveSegmenter(calibration, light_passes=0)
    for white_balance, min_gain in (((1.25, 1.0, 0.8), 0.05), ((0.8, 1.0, 1.25), 0.03),
                                    ((1.0, 1.0, 1.0), -0.002)):
        acc = []
        for _ in range(3):
            img, lab = render_blob_frame(rng, BlobConditions(1.0, white_balance, 3.0, 6, True,
                                                             1.4))
            g = lab > 0
            acc.append([np.mean(seg.classify_full(img)[g] == lab[g])
                        for seg in (corrected, plain)])
            assert corrected.process(img).hand_found
        with_light, without = np.mean(acc, axis=0)
        assert with_light > without + min_gain, white_balance
        assert with_light > 0.95
    with pytest.raises(SegmentationConfigError, match='light_passes'):
        GloveSegmenter(calibration, light_passes=-1)


def test_eval_frames_with_clutter_near_the_hand() -> None:
    """--clutter-near-hand renders the same hands with the distractors placed anywhere."""
    away = held_out_frames('synth', 8, seed=3)
    near = held_out_frames('synth', 8, seed=3, clutter_near_hand=True)
    for (_, labels_away, _), (_, labels_near, _) in zip(away, near, strict=True):
        np.testing.assert_array_equal(labels_away, labels_near)
    assert any(not np.array_equal(a[0], n[0]) for a, n in zip(away, near, strict=True))


def test_roi_reduction_keeps_crop_consistent(calibration) -> None:
    """A big glove is processed at reduced resolution; the crop must still match."""
    rng = np.random.default_rng(21)
    img, lab = render_blob_frame(rng, BlobConditions(1.0, (1.0, 1.0, 1.0), 2.0, 3, False, 2.2))
    # the frame's glove-coloured clutter shares the glove's exact colours: the scene-colour
    # filter would take those patches off the glove too, which is not what this test is about
    exact = dict(scene_colour_min_share=0.0)
    fine = GloveSegmenter(calibration, max_roi_cells=400, **exact).process(img)
    coarse = GloveSegmenter(calibration, max_roi_cells=60, **exact).process(img)
    truth = crop_to_tiny(lab)
    for obs in (fine, coarse):
        assert obs.hand_found
        err = np.hypot(*np.subtract(obs.crop.center_xy, truth.transform.center_xy))
        assert err < 0.06 * truth.transform.half_size
        assert obs.crop.half_size == pytest.approx(truth.transform.half_size, rel=0.1)


def test_tools_calibrate_and_evaluate(tmp_path: Path, capsys) -> None:
    rng = np.random.default_rng(4)
    frames = [render_blob_frame(rng, sample_blob_conditions(rng, 'train'), 320, 240)
              for _ in range(8)]
    write_labelled_frames(tmp_path / 'frames', frames)
    back = read_labelled_frames(tmp_path / 'frames')
    assert len(back) == 8
    np.testing.assert_array_equal(back[3][0], frames[3][0])
    np.testing.assert_array_equal(back[3][1], frames[3][1])
    cal_path = tmp_path / 'cal.npz'
    assert calibrate_colors.main(['--frames', str(tmp_path / 'frames'), '--output',
                                  str(cal_path), '--bits', '5', '--max-pixels', '1000']) == 0
    config = tmp_path / 'color.yaml'
    config.write_text(f'calibration_file: {cal_path}\nsegmenter:\n  min_glove_pixels: 200\n')
    seg = load_segmenter(str(config))
    assert seg.min_glove_pixels == 200
    out = tmp_path / 'eval.json'
    assert eval_segmentation.main(['--config', str(config), '--source', 'blobs', '--frames',
                                   '3', '--empty', '1', '--repeats', '1', '--json',
                                   str(out)]) == 0
    figures = json.loads(out.read_text())
    s = figures['summary']
    assert s['frames'] == 4 and s['hand_detect_tn'] == 1
    assert 0.5 < s['interior_pixel_accuracy'] <= 1.0
    assert 'crop_iou_mean' in s and len(figures['timings']) == len(STAGES) + 1
    assert 0.0 <= s['pipeline_background_fp_rate'] <= 1.0
    assert all(np.isfinite(row['glove_median_ms']) for row in figures['timings'])
    # every missed glove pixel is counted once by what it became and once by where it is
    missed = 1.0 - s['glove_pixel_accuracy']
    assert s['miss_as_background'] + s['miss_as_other_colour'] == pytest.approx(missed)
    assert s['miss_silhouette'] + s['miss_colour_border'] + s['miss_interior'] == (
        pytest.approx(missed))
    assert {row['condition'] for row in figures['conditions']} == {'light level',
                                                                   'sensor noise'}
    assert sum(row['frames'] for row in figures['conditions']
               if row['condition'] == 'light level') == 3     # the glove frames
    assert [row['when'] for row in figures['machine_speed']] == ['before', 'after']
    printed = capsys.readouterr().out
    assert 'time per 640x480 frame' in printed and MACHINE_SPEED_TITLE in printed
    # glove-like clutter next to the hand exists only in the synthetic frames
    assert eval_segmentation.main(['--config', str(config), '--source', 'blobs',
                                   '--clutter-near-hand']) == 1
    assert 'needs source' in capsys.readouterr().err
    config.write_text(f'calibration_file: {cal_path}\nsegmenter:\n  no_such_key: 1\n')
    with pytest.raises(SegmentationConfigError, match='no_such_key'):
        load_segmenter(str(config))
    # a missing calibration is a clean error, not a traceback
    config.write_text(f'calibration_file: {tmp_path / "none.npz"}\n')
    assert eval_segmentation.main(['--config', str(config), '--frames', '1']) == 1
