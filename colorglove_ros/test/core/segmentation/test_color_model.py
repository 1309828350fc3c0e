"""Tests for the CGZ colour space, the glove colour calibration and its file format."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from segmentation_samples import FAST_FIT

from colorglove_ros.core.colorimetry import linear_rgb_to_xyz, linear_to_srgb, srgb_to_linear
from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB
from colorglove_ros.core.segmentation.calibration_fit import fit_color_calibration, processed_copies
from colorglove_ros.core.segmentation.color_model import (
    CALIBRATION_FORMAT_VERSION,
    CGZ_A,
    ColorCalibrationError,
    cgz_chroma,
    cgz_intensity_axis,
    load_calibration,
    lut_index,
    rgb_to_cgz,
    save_calibration,
    xyz_to_cgz,
)
from colorglove_ros.core.segmentation.light import (
    LIGHT_TEMPERATURES_K,
    estimate_light_gains,
    gain_table,
    planckian_illuminants,
)
from colorglove_ros.core.synthetic.blob_glove import (
    BlobConditions,
    render_blob_frame,
    sample_blob_conditions,
)
from colorglove_ros.core.synthetic.conditions import FrameConditions
from colorglove_ros.core.synthetic.frames import camera_encode


@pytest.fixture(scope='module')
def frames() -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    rng = np.random.default_rng(7)
    train = [render_blob_frame(rng, sample_blob_conditions(rng, 'train'), 320, 240)
             for _ in range(8)]
    held = [render_blob_frame(rng, sample_blob_conditions(rng, 'train'), 320, 240)
            for _ in range(3)]
    return {'train': train, 'held': held}


@pytest.fixture(scope='module')
def calibration(frames):
    return fit_color_calibration(frames['train'], seed=0, **FAST_FIT)


def test_srgb_linear_xyz_reference_values() -> None:
    np.testing.assert_allclose(srgb_to_linear(np.array([0, 255, 128]) / 255.0),
                               [0.0, 1.0, 0.2158605], atol=1e-6)
    # D65 white point
    np.testing.assert_allclose(linear_rgb_to_xyz(np.ones(3)), [0.95047, 1.0, 1.08883],
                               atol=1e-4)


def test_cgz_light_level_is_a_translation_along_intensity_axis() -> None:
    rng = np.random.default_rng(1)
    xyz = rng.uniform(0.05, 0.8, (50, 3))
    for k in (0.3, 2.5):
        d = xyz_to_cgz(k * xyz) - xyz_to_cgz(xyz)
        # every point moves by ln(k) * A 1
        np.testing.assert_allclose(d, np.tile(np.log(k) * CGZ_A @ np.ones(3), (50, 1)),
                                   atol=1e-9)
        c0, i0 = cgz_chroma(xyz_to_cgz(xyz))
        c1, i1 = cgz_chroma(xyz_to_cgz(k * xyz))
        np.testing.assert_allclose(c1, c0, atol=1e-9)
        np.testing.assert_allclose(i1 - i0, np.log(k) * np.linalg.norm(CGZ_A @ np.ones(3)),
                                   atol=1e-9)
    assert np.linalg.norm(cgz_intensity_axis()) == pytest.approx(1.0)


def test_cgz_vectorised_and_finite_on_black() -> None:
    img = np.zeros((4, 5, 3), np.uint8)
    img[0, 0] = (255, 255, 255)
    img[1, 1] = (255, 0, 0)
    out = rgb_to_cgz(img)
    assert out.shape == (4, 5, 3)
    assert np.all(np.isfinite(out))
    # the palette colours are far apart in CGZ space (well separated classes)
    p = rgb_to_cgz(GLOVE_PALETTE_RGB)
    d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(len(p)) * 1e9
    assert d.min() > 5.0


def test_lut_index_layout() -> None:
    rgb = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [4, 8, 12]], np.uint8)
    np.testing.assert_array_equal(lut_index(rgb, 6),
                                  [63 << 12, 63 << 6, 63, (1 << 12) | (2 << 6) | 3])


def test_calibration_classifies_held_out_frames(calibration, frames) -> None:
    k3 = np.ones((3, 3), np.uint8)
    correct = total = fp = bg = 0
    for img, lab in frames['held']:
        pred = calibration.classify(cv2.bilateralFilter(img, 5, 30, 3))
        assert pred.shape == lab.shape and pred.dtype == np.uint8
        interior = (cv2.erode(lab, k3) == cv2.dilate(lab, k3)) & (lab > 0)
        correct += int((pred[interior] == lab[interior]).sum())
        total += int(interior.sum())
        fp += int((pred[lab == 0] > 0).sum())
        bg += int((lab == 0).sum())
    assert correct / total > 0.93
    assert fp / bg < 0.03


def _interior_accuracy_and_fp(calibration, frames) -> tuple[float, float]:
    k3 = np.ones((3, 3), np.uint8)
    correct = total = fp = bg = 0
    for img, lab in frames:
        pred = calibration.classify(cv2.bilateralFilter(img, 5, 30, 3))
        interior = (cv2.erode(lab, k3) == cv2.dilate(lab, k3)) & (lab > 0)
        correct += int((pred[interior] == lab[interior]).sum())
        total += int(interior.sum())
        fp += int((pred[lab == 0] > 0).sum())
        bg += int((lab == 0).sum())
    return correct / total, fp / bg


def test_planckian_illuminants_follow_the_black_body_locus() -> None:
    gains = planckian_illuminants(2856.0, 20000.0, count=9)
    assert gains.shape == (9, 3) and np.all(gains > 0)
    red_blue = np.log(gains[:, 0] / gains[:, 2])
    # from incandescent (much more red than blue) through neutral to blue-sky shade
    assert red_blue[0] > 1.8 and red_blue[-1] < -0.8
    assert np.all(np.diff(red_blue) < 0)
    np.testing.assert_allclose(planckian_illuminants(6500.0, 6500.0, count=2), 1.0, atol=1e-6)
    with pytest.raises(ColorCalibrationError):
        planckian_illuminants(5000.0, 3000.0)


def test_relighting_under_black_bodies_covers_tinted_light(frames) -> None:
    """Fitted on neutral-light frames only, re-lighting under black-body lights must carry
    the colours to a strongly warm light without claiming more background under neutral
    light."""
    plain, tinted = (fit_color_calibration(frames['train'], seed=0, bits=5, max_per_class=1000,
                                           background_components=6, augment_temperatures_k=t)
                     for t in (None, LIGHT_TEMPERATURES_K))   # everyday lights, no correction
    rng = np.random.default_rng(9)
    warm = [render_blob_frame(rng, BlobConditions(1.0, (1.2, 1.0, 0.8), 2.0, 6, True, 1.4),
                              320, 240) for _ in range(3)]
    acc_plain, _ = _interior_accuracy_and_fp(plain, warm)
    acc_tinted, _ = _interior_accuracy_and_fp(tinted, warm)
    assert acc_tinted > max(acc_plain + 0.1, 0.9)
    _, fp_plain = _interior_accuracy_and_fp(plain, frames['held'])
    _, fp_tinted = _interior_accuracy_and_fp(tinted, frames['held'])
    assert fp_tinted < fp_plain + 0.005
    with pytest.raises(ColorCalibrationError, match='colour temperature'):
        fit_color_calibration(frames['train'], augment_temperatures_k=(6500.0, 3000.0), **FAST_FIT)


WASHED_OUT = FrameConditions(saturation=0.6, gamma=1.2, contrast=0.4)
"""Another camera's colour processing that washes the glove's colours out."""


def _seen_by(look: FrameConditions, frames):
    return [(camera_encode(srgb_to_linear(img / 255.0).astype(np.float32), look), lab)
            for img, lab in frames]


def test_processed_copies_are_seeded_and_cover_washed_out_colours() -> None:
    """Processed copies: ``copies`` times the pixels, the same for the same seed, and some
    with the palette's yellow washed out towards grey (less chroma)."""
    yellow = np.tile(np.array(GLOVE_PALETTE_RGB[3], np.uint8), (400, 1))
    args = ((0.8, 1.2), 0.1, None, 2.0)
    a = processed_copies(yellow, np.random.default_rng(3), 2, *args)
    b = processed_copies(yellow, np.random.default_rng(3), 2, *args)
    assert a.shape == (800, 3) and a.dtype == np.uint8 and np.array_equal(a, b)
    chroma = a.max(axis=1).astype(int) - a.min(axis=1)
    assert chroma.min() < 0.75 * (int(yellow[0].max()) - int(yellow[0].min()))
    assert processed_copies(yellow, np.random.default_rng(3), 0, *args).shape == (0, 3)


def test_processed_copies_cover_washed_out_frames(frames) -> None:
    """Trained with copies seen through other cameras' processing, the model must label more
    of a washed-out camera's glove, without claiming more background of plain frames."""
    plain, processed = (fit_color_calibration(frames['train'], seed=0, bits=5,
                                              max_per_class=1000, background_components=6,
                                              augment_processed_copies=n,
                                              augment_processed_colors=None) for n in (0, 2))
    washed = _seen_by(WASHED_OUT, frames['held'])
    acc_plain, _ = _interior_accuracy_and_fp(plain, washed)
    acc_processed, _ = _interior_accuracy_and_fp(processed, washed)
    assert acc_processed > acc_plain + 0.05
    _, fp_plain = _interior_accuracy_and_fp(plain, frames['held'])
    _, fp_processed = _interior_accuracy_and_fp(processed, frames['held'])
    assert fp_processed < fp_plain + 0.005
    assert processed.metadata['augment_processed_copies'] == 2


def test_unseen_colours_fall_to_background(calibration) -> None:
    greys = np.array([[0, 0, 0], [128, 128, 128], [255, 255, 255], [90, 60, 40]], np.uint8)
    assert np.all(calibration.classify(greys[None])[0] == 0)
    # the pure palette colours are recognised
    labels = calibration.classify(GLOVE_PALETTE_RGB[None])[0]
    assert np.mean(labels == np.arange(1, 11)) >= 0.9


def test_lut_matches_exact_decision_at_bin_centres(calibration) -> None:
    rng = np.random.default_rng(3)
    step = 256 >> calibration.bits
    bins = rng.integers(0, 1 << calibration.bits, (300, 3))
    centres = bins * step + (step - 1) / 2.0
    exact = calibration.decide(centres / 255.0)
    via_lut = calibration.classify((bins * step).astype(np.uint8)[None])[0]
    np.testing.assert_array_equal(via_lut, exact)


def test_save_load_roundtrip(calibration, tmp_path: Path) -> None:
    path = save_calibration(calibration, tmp_path / 'cal.npz')
    loaded = load_calibration(path)
    np.testing.assert_array_equal(loaded.lut, calibration.lut)
    assert loaded.bits == calibration.bits and loaded.num_colors == 10
    assert loaded.metadata['num_frames'] == 8
    img = np.random.default_rng(0).integers(0, 256, (20, 30, 3)).astype(np.uint8)
    np.testing.assert_array_equal(loaded.classify(img), calibration.classify(img))
    np.testing.assert_allclose(loaded.log_likelihoods(img[0]),
                               calibration.log_likelihoods(img[0]))
    np.testing.assert_array_equal(loaded.reference_linear_rgb, calibration.reference_linear_rgb)


@pytest.mark.parametrize('num_colors', [0, 64])
def test_a_calibration_with_more_colours_than_the_kernels_take_is_refused(
        calibration, tmp_path: Path, num_colors: int) -> None:
    path = save_calibration(calibration, tmp_path / 'cal.npz')
    arrays = dict(np.load(path, allow_pickle=False))
    arrays['num_colors'] = np.array(num_colors)
    np.savez(path, **arrays)
    with pytest.raises(ColorCalibrationError, match='at most 63'):
        load_calibration(path)


def test_reference_colours_are_the_training_colours(calibration) -> None:
    ref = calibration.reference_linear_rgb
    assert ref.shape == (10, 3)
    # blob frames: palette colours, shaded 0.7..1 and lit at 0.75..1.15 -> same hue, dimmer
    palette = srgb_to_linear(GLOVE_PALETTE_RGB / 255.0)
    dominant = np.argmax(palette, axis=1)
    assert np.mean(np.argmax(ref, axis=1) == dominant) >= 0.9
    ratio = ref.sum(axis=1) / palette.sum(axis=1)
    assert np.all((ratio > 0.3) & (ratio < 1.2))


def test_linear_to_srgb_inverts_srgb_to_linear() -> None:
    levels = np.arange(256, dtype=np.uint8)
    np.testing.assert_allclose(255.0 * linear_to_srgb(srgb_to_linear(levels / 255.0)), levels,
                               atol=1e-6)


@pytest.mark.parametrize('light', [(1.6, 1.0, 0.55), (0.7, 1.0, 1.5), (1.0, 1.0, 1.0)])
def test_light_gains_undo_a_tinted_light(light) -> None:
    """Glove pixels = own shading * light * reference colour (+ noise, + a few pixels of a
    wrong label): the gains must bring them back to the reference colours' hue."""
    rng = np.random.default_rng(2)
    ref = srgb_to_linear(GLOVE_PALETTE_RGB / 255.0)
    labels = rng.integers(1, 11, 3000)
    # per-pixel and per-colour shading, low enough that no channel clips at white
    shading = rng.uniform(0.2, 0.6, (3000, 1)) * rng.uniform(0.5, 1.0, 11)[labels, None]
    pix = shading * np.asarray(light) * ref[labels - 1] + rng.normal(0.0, 0.004, (3000, 3))
    wrong = rng.choice(3000, 60, replace=False)
    labels_seen = labels.copy()
    labels_seen[wrong] = rng.integers(1, 11, 60)
    gains = estimate_light_gains(np.clip(pix, 0.0, 1.0), labels_seen, ref)
    expected = 1.0 / np.asarray(light)
    expected /= np.exp(np.log(expected) @ [0.2126, 0.7152, 0.0722])   # luminance-neutral
    np.testing.assert_allclose(gains, expected, rtol=0.05)
    # too few colours to tell a light from the glove's own colours: no correction
    few = np.isin(labels_seen, (1, 2))
    np.testing.assert_array_equal(estimate_light_gains(pix[few], labels_seen[few], ref), 1.0)


def test_gain_table_scales_linear_rgb() -> None:
    levels = np.arange(256, dtype=np.uint8)
    np.testing.assert_array_equal(gain_table(np.ones(3))[0], np.repeat(levels[:, None], 3, 1))
    table = gain_table(np.array([2.0, 1.0, 0.5]))
    assert table.shape == (1, 256, 3) and table.dtype == np.uint8
    lin = srgb_to_linear(table[0] / 255.0)
    mid = srgb_to_linear(100 / 255.0)
    np.testing.assert_allclose(lin[100], [2.0 * mid, mid, 0.5 * mid], rtol=0.02)
    assert table[0, 255, 0] == 255   # clipped at white


def test_load_errors(calibration, tmp_path: Path) -> None:
    with pytest.raises(ColorCalibrationError, match='not found'):
        load_calibration(tmp_path / 'missing.npz')
    bad = tmp_path / 'garbage.npz'
    bad.write_bytes(b'not a zip file at all')
    with pytest.raises(ColorCalibrationError, match='cannot read'):
        load_calibration(bad)
    other = tmp_path / 'other.npz'
    np.savez(other, x=np.zeros(3))
    with pytest.raises(ColorCalibrationError, match='not a colour calibration'):
        load_calibration(other)
    good = save_calibration(calibration, tmp_path / 'v.npz')
    with np.load(good) as z:
        data = {k: z[k] for k in z.files}
    data['version'] = np.array(CALIBRATION_FORMAT_VERSION + 1)
    np.savez(tmp_path / 'v2.npz', **data)
    with pytest.raises(ColorCalibrationError, match='version'):
        load_calibration(tmp_path / 'v2.npz')
    # a version-1 file (before the reference colours): a clear error, not a KeyError
    old = {k: v for k, v in data.items() if k != 'reference_linear_rgb'}
    old['version'] = np.array(1)
    np.savez(tmp_path / 'v1.npz', **old)
    with pytest.raises(ColorCalibrationError, match='version 1, expected 2; re-run'):
        load_calibration(tmp_path / 'v1.npz')
    del data['lut']
    data['version'] = np.array(CALIBRATION_FORMAT_VERSION)
    np.savez(tmp_path / 'nolut.npz', **data)
    with pytest.raises(ColorCalibrationError, match='corrupt'):
        load_calibration(tmp_path / 'nolut.npz')


def test_fit_input_errors(frames) -> None:
    with pytest.raises(ColorCalibrationError, match='at least 8'):
        fit_color_calibration(frames['train'][:3])
    img, lab = frames['train'][0]
    with pytest.raises(ColorCalibrationError, match='mask shape'):
        fit_color_calibration([(img, lab[:-1])] * 8)
    with pytest.raises(ColorCalibrationError, match='uint8'):
        fit_color_calibration([(img.astype(np.float32), lab)] * 8)


def test_calibrate_colors_processed_copies_option(frames, tmp_path: Path) -> None:
    """``colorglove_calibrate_colors --processed-copies N --processed-colors ...`` fits with N
    processed copies of those colours (in the file's metadata) and refuses a negative N."""
    from colorglove_ros.core.segmentation.calibration_fit import write_labelled_frames
    from colorglove_ros.tools import calibrate_colors

    write_labelled_frames(tmp_path / 'frames', frames['train'])
    out = tmp_path / 'cal.npz'
    assert calibrate_colors.main(['--frames', str(tmp_path / 'frames'), '--output', str(out),
                                  '--bits', '4', '--max-pixels', '300',
                                  '--processed-copies', '1', '--processed-colors', 'yellow',
                                  'lime']) == 0
    meta = load_calibration(out).metadata
    assert meta['augment_processed_copies'] == 1 and meta['augment_processed_colors'] == [4, 10]
    with pytest.raises(SystemExit):
        calibrate_colors.main(['--frames', str(tmp_path / 'frames'), '--processed-copies', '-1'])


def test_processed_copies_only_for_the_colours_named(frames) -> None:
    """With ``augment_processed_colors`` only those glove colours (and the background) are
    widened: red alone recovers washed-out red, and washed-out green stays as the plain fit
    labels it."""
    fit = dict(seed=0, bits=5, max_per_class=1000, background_components=6)
    plain = fit_color_calibration(frames['train'], **fit)
    red = fit_color_calibration(frames['train'], augment_processed_copies=2,
                                augment_processed_colors=[1], **fit)
    washed = _seen_by(WASHED_OUT, frames['held'])
    k3 = np.ones((3, 3), np.uint8)
    for c, better in ((1, True), (2, False)):
        hits = []
        for cal in (plain, red):
            correct = total = 0
            for img, lab in washed:
                pred = cal.classify(cv2.bilateralFilter(img, 5, 30, 3))
                inside = (cv2.erode(lab, k3) == cv2.dilate(lab, k3)) & (lab == c)
                correct += int((pred[inside] == c).sum())
                total += int(inside.sum())
            hits.append(correct / max(total, 1))
        assert (hits[1] > hits[0] + 0.2) if better else (hits[1] <= hits[0] + 0.05), (c, hits)
