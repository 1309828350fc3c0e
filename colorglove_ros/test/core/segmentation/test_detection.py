"""Finding the glove, not its colours (core/segmentation/detection.py and its use in the
segmenter): colourful hand-sized patchworks are kept, wide single-colour surfaces and
few-colour textures are not."""
from __future__ import annotations

import numpy as np
import pytest
from segmentation_samples import printed_glove_calibration

from colorglove_ros.core.hand.glove import GLOVE_PALETTE_RGB, default_colour_adjacency
from colorglove_ros.core.segmentation.color_model import index_tables
from colorglove_ros.core.segmentation.crop import compiled_kernels
from colorglove_ros.core.segmentation.detection import (
    LARGEST_PATCH_WINDOW_SHARE,
    colour_diversity,
    drop_oversized_components,
    glove_region_mask,
    junction_window,
    keep_near_junctions,
    rejected_scene_colours,
    scene_colour_table,
    shed_oversized_patches,
    unsupported_regions,
)
from colorglove_ros.core.segmentation.segmenter import GloveSegmenter
from colorglove_ros.core.synthetic import frames as synth
from colorglove_ros.core.synthetic.conditions import FrameConditions


def _patchwork(h: int = 24, w: int = 24, colours: int = 8) -> np.ndarray:
    """A glove-like block of 4x4 patches cycling through ``colours`` colours."""
    yy, xx = np.mgrid[0:h, 0:w]
    return (((yy // 4) * 3 + (xx // 4)) % colours + 1).astype(np.uint8)


def test_diversity_tells_a_patchwork_from_a_two_colour_texture() -> None:
    labels = np.zeros((60, 120), np.uint8)
    labels[10:34, 10:34] = _patchwork()
    labels[10:50, 70:110] = np.where(np.arange(40)[:, None] % 6 < 3, 1, 2)   # red/orange
    counts = colour_diversity(labels, 10, 12, 0.02)
    assert counts[22, 22] >= 6 and counts[30, 90] <= 2


def test_region_mask_keeps_the_glove_and_its_long_finger_drops_far_texture() -> None:
    labels = np.zeros((80, 160), np.uint8)
    labels[10:34, 10:34] = _patchwork()
    labels[20:24, 34:70] = 3                          # a long finger reaching from the glove
    labels[40:78, 100:158] = np.where(np.arange(58)[None, :] % 8 < 4, 1, 2)
    mask = glove_region_mask(labels, 10, 12, 6, 0.02)
    assert mask[10:34, 10:34].all() and mask[20:24, 34:70].all()
    assert not mask[60:78, 130:158].any()
    assert not glove_region_mask(labels[40:], 10, 12, 6, 0.02).any()


def _region_mask_by_dilation(labels: np.ndarray, window: int, min_colors: int,
                             density: float) -> np.ndarray:
    """glove_region_mask written out with a morphological dilation (the reference)."""
    import cv2

    rich = colour_diversity(labels, 10, window, density) >= min_colors
    size = 2 * window + 1
    near = cv2.dilate(rich.view(np.uint8),
                      cv2.getStructuringElement(cv2.MORPH_RECT, (size, size))).view(bool)
    n, comp = cv2.connectedComponents((labels > 0).view(np.uint8), connectivity=8)
    reached = np.zeros(n, bool)
    reached[comp[rich]] = True
    reached[0] = False
    return near | reached[comp]


@pytest.mark.parametrize('seed', range(6))
@pytest.mark.parametrize('window', [5, 12, 24, 40])
def test_region_mask_margin_is_the_square_dilation(seed: int, window: int) -> None:
    """The margin around colourful windows is exactly a (2 window + 1)-square dilation,
    up to the image's edges, on random patchworks with noise and holes."""
    rng = np.random.default_rng(seed)
    h, w = 250, 300
    labels = np.where(rng.random((h, w)) < 0.97, 0, rng.integers(1, 11, (h, w))).astype(np.uint8)
    y, x = rng.integers(0, h - 30), rng.integers(0, w - 30)
    labels[y:y + 30, x:x + 30] = _patchwork(30, 30, 10)
    for min_colors in (3, 4):
        mask = glove_region_mask(labels, 10, window, min_colors, 0.02)
        np.testing.assert_array_equal(mask, _region_mask_by_dilation(labels, window, min_colors,
                                                                     0.02))
        assert mask.any() and not mask.all()   # a margin with an edge inside the image


def test_oversized_single_colour_regions_are_background() -> None:
    labels = np.zeros((100, 100), np.uint8)
    labels[:, :60] = 1                                # a table top, 6000 px
    labels[70:80, 70:80] = 1                          # a patch of the same colour, 100 px
    out = drop_oversized_components(labels, 1000)
    assert not out[:, :60].any() and out[70:80, 70:80].all()
    assert drop_oversized_components(labels, 0) is labels


def test_a_surface_touching_the_glove_is_trimmed_to_the_hand() -> None:
    """A single-colour surface touching a glove patchwork keeps only its part within reach
    of the patch junctions, so the crop's window shrinks to about the hand's; the patchwork
    and a long one-colour finger (a patch-sized region) stay whole; reach 0 or no junction
    changes nothing."""
    from colorglove_ros.core.segmentation.crop import mean_shift_crop

    labels = np.zeros((160, 200), np.uint8)
    labels[60:84, 60:84] = _patchwork()
    labels[70:74, 84:104] = 9                     # a finger: one colour, reaching out
    labels[20:158, 20:60] = 2                     # an orange surface along the glove's side
    out = keep_near_junctions(labels, 10, 0.5, 2)
    assert (out[60:84, 60:84] == labels[60:84, 60:84]).all()
    assert (out[70:74, 84:104] == 9).all()
    assert not out[20:40, 20:60].any() and not out[130:158, 20:60].any()
    assert out[64:80, 54:60].all()                # the surface's edge beside the hand stays
    glove_half = mean_shift_crop(labels[60:84, 60:104] > 0)[1]
    assert mean_shift_crop(labels)[1] > 3.0 * glove_half
    assert mean_shift_crop(out)[1] < 1.5 * glove_half
    assert keep_near_junctions(labels, 10, 0.0, 2) is labels
    plain = np.where(labels == 2, 2, 0).astype(np.uint8)
    assert keep_near_junctions(plain, 10, 0.5, 2) is plain


def test_with_edges_only_a_surface_running_off_the_image_is_trimmed() -> None:
    """``edges``: a single-colour region along the glove that runs off the image's bottom (a
    sleeve) is trimmed to the junctions' reach; the same region ending inside the image, or
    running off a side that is not the image's border, stays whole."""
    labels = np.zeros((160, 120), np.uint8)
    labels[40:64, 40:64] = _patchwork()
    labels[64:160, 44:60] = 1                     # a red sleeve down to the bottom row
    bottom = (False, False, False, True)
    out = keep_near_junctions(labels, 10, 0.5, 2, edges=bottom)
    assert (out[40:64, 40:64] == labels[40:64, 40:64]).all()
    assert out[64:68, 44:60].all() and not out[120:160, 44:60].any()
    assert (keep_near_junctions(labels, 10, 0.5, 2, edges=(True, True, True, False))
            == labels).all()
    inside = labels.copy()
    inside[150:160] = 0                           # the same region, ending inside the image
    assert (keep_near_junctions(inside, 10, 0.5, 2, edges=bottom) == inside).all()
    cut = np.zeros((160, 120), np.uint8)          # a glove cut by the bottom border: its large
    cut[100:160, 30:90] = np.where(np.arange(60)[None, :] % 20 < 10, 3, 4)   # patch among
    cut[110:160, 50:70] = 1                       # its neighbours stays whole
    cut[100:124, 30:54] = _patchwork()
    kept = keep_near_junctions(cut, 10, 0.05, 2, edges=bottom)
    assert (kept[110:160, 50:70] == cut[110:160, 50:70]).all()


def test_with_surfaces_only_a_large_glove_patch_stays_and_a_touching_surface_goes() -> None:
    """``surfaces_only``: with a share small enough to reach a large printed patch, the
    patch (surrounded by other glove colours) keeps every pixel however far from a junction,
    while a single-colour surface of about that size touching the glove (outline along
    background) is still trimmed to the junctions' reach; without it the patch's middle goes
    too."""
    labels = np.zeros((120, 160), np.uint8)
    labels[30:78, 30:78] = np.tile(_patchwork(), (2, 2))
    labels[42:66, 42:66] = 9                      # a large patch among its neighbours
    labels[40:68, 78:118] = 2                     # an orange petal touching the glove
    out = keep_near_junctions(labels, 10, 0.15, 2, 0.05, surfaces_only=True)
    assert (out[42:66, 42:66] == 9).all()
    assert (out[30:78, 30:78] == labels[30:78, 30:78]).all()
    assert out[50:58, 78:82].all() and not out[40:68, 100:118].any()
    cut = keep_near_junctions(labels, 10, 0.15, 2, 0.05)
    assert not (cut[42:66, 42:66] == 9).all()
    assert not cut[40:68, 100:118].any()


def test_with_min_pull_only_a_pulled_crop_is_trimmed() -> None:
    """``min_pull``: a glove alone (its window about the junctions') keeps every pixel, even
    a one-colour finger at its silhouette that the trim would cut back without the gate;
    with a surface joined to it (the glove's window several times the junctions') the
    surface is trimmed as without the gate and the glove stays."""
    labels = np.zeros((160, 200), np.uint8)
    labels[60:84, 60:84] = _patchwork()
    labels[68:74, 84:116] = 9                     # a finger: background along its sides
    trim = {'max_patch_share': 0.05, 'surfaces_only': True}
    assert not (keep_near_junctions(labels, 10, 0.35, 2, **trim)[68:74, 84:116] == 9).all()
    assert keep_near_junctions(labels, 10, 0.35, 2, **trim, min_pull=1.5) is labels
    pulled = labels.copy()
    pulled[20:158, 20:60] = 2                     # an orange surface along the glove's side
    out = keep_near_junctions(pulled, 10, 0.35, 2, **trim, min_pull=1.5)
    assert (out == keep_near_junctions(pulled, 10, 0.35, 2, **trim)).all()
    assert not out[20:40, 20:60].any() and not out[130:158, 20:60].any()
    assert (out[60:84, 60:84] == labels[60:84, 60:84]).all()


def test_a_surface_touching_the_glove_is_shed_at_the_hand_scale() -> None:
    """A single-colour surface touching a glove patchwork, too small for the image-wide
    limit but larger than any patch at the hand's scale (found from the patch junctions),
    goes; the patchwork stays, and so does a large patch surrounded by other glove colours;
    without any patch junction there is no window."""
    labels = np.zeros((120, 160), np.uint8)
    labels[40:64, 40:64] = _patchwork()
    labels[30:90, 64:110] = 2                     # an orange petal touching the glove
    window = junction_window(labels, 10, 2)
    (cx, cy), half = window
    assert abs(cx - 52) < 8 and abs(cy - 52) < 8 and half < 30
    out = shed_oversized_patches(labels, 0.15, window)
    assert not out[30:90, 66:110].any()
    assert (out[40:64, 40:64] == labels[40:64, 40:64]).mean() > 0.9
    surrounded = labels.copy()
    surrounded[44:60, 44:60] = 5                  # as large as the petal's share, inside
    surrounded[30:90, 64:110] = 0
    assert (shed_oversized_patches(surrounded, 0.05, window)[44:60, 44:60] == 5).all()
    assert not shed_oversized_patches(labels, 0.05, window)[30:90, 66:110].any()
    plain = np.where(labels == 2, 2, 0).astype(np.uint8)
    assert junction_window(plain, 10, 2) is None
    assert shed_oversized_patches(plain, 0.15, None) is plain
    assert shed_oversized_patches(labels, 0.0, window) is labels


def test_scene_colour_table_counts_quantised_colours() -> None:
    rgb = np.array([[200, 30, 30]] * 5 + [[30, 200, 30]] * 2, np.uint8)
    table = scene_colour_table(rgb, 5, 3)
    assert table.shape == (1 << 15,) and table.sum() == 1
    assert table[(200 >> 3) << 10 | (30 >> 3) << 5 | (30 >> 3)]


@pytest.mark.parametrize('trial', range(24))
def test_rejected_scene_colours_are_the_histogram_of_the_classified_less_the_kept(
        trial: int) -> None:
    """The scene colours in one compiled pass (``rejected_scene_colours``) against the
    segmenter's former steps: the image classified whole (``classify``, no scene colours),
    its glove pixels less those the region's kept labels keep, and their histogram
    (``scene_colour_table`` with ``where``): the same table for random tables and light
    corrections, regions anywhere (at the image's edges, the whole image, one pixel), strided
    images, and thresholds from one pixel up."""
    rng = np.random.default_rng(trial)
    h, w = (int(v) for v in rng.integers(1, 50, 2))
    image = rng.integers(0, 256, (h, w + 3, 3), dtype=np.uint8)
    image[:, ::2] //= 8                        # repeated colours, so that some reach the count
    image = image[:, 1:w + 1] if trial % 3 else np.ascontiguousarray(image[:, :w])
    bits = 4
    lut = (rng.random(1 << (3 * bits)) < 0.6).astype(np.uint8) * rng.integers(
        1, 11, 1 << (3 * bits), dtype=np.uint8)
    light = None if trial % 2 else rng.integers(0, 256, (1, 256, 3), dtype=np.uint8)
    index = index_tables(bits, light)
    y0, x0 = int(rng.integers(0, h)), int(rng.integers(0, w))
    y1, x1 = int(rng.integers(y0 + 1, h + 1)), int(rng.integers(x0 + 1, w + 1))
    if trial % 8 == 0:
        y0, x0, y1, x1 = 0, 0, h, w
    kept = np.where(rng.random((y1 - y0, x1 - x0)) < 0.5, 0,
                    rng.integers(1, 11, (y1 - y0, x1 - x0))).astype(np.uint8)
    min_pixels = (0.5, 1.0, 2.0, 0.001 * h * w)[trial % 4]
    rejected = compiled_kernels().classify(image, lut, index, np.zeros(0, bool),
                                           index_tables(5)) > 0
    rejected[y0:y1, x0:x1] &= kept == 0
    want = scene_colour_table(image, 5, min_pixels, rejected)
    got = rejected_scene_colours(image, lut, index, kept, (x0, y0), 5, min_pixels)
    assert got.dtype == want.dtype and np.array_equal(got, want)
    if min_pixels <= 1.0:            # (not vacuous: every rejected pixel's colour is in)
        assert want.sum() >= min(1, int(rejected.sum()))


@pytest.fixture(scope='module')
def calibration():
    return printed_glove_calibration()


def _rendered_glove(wrist_m: tuple[float, float, float], seed: int = 4) -> synth.SyntheticFrame:
    """A rendered glove (the pose of ``seed``), fully in view, its wrist at ``wrist_m`` in the
    camera frame."""
    camera = synth.default_camera()
    rng = np.random.default_rng(seed)
    q = synth.sample_pose(rng, camera, out_of_frame_prob=0.0)
    q[0:3] = wrist_m
    return synth.render_frame(q, camera, rng, FrameConditions())


def test_a_glove_in_front_of_a_warm_wood_like_surface_is_found(calibration) -> None:
    """A rendered glove beside a surface grained in four of the glove's colours: with the
    detection the crop is on the hand; with it off the surface pulls the crop away."""
    frame = _rendered_glove((0.12, 0.05, 0.6))
    image = frame.image_rgb.copy()
    yy, xx = np.mgrid[0:480, 0:260]
    grain = ((yy + 7 * np.sin(xx / 13.0)) // 9).astype(int) % 4     # wavy grain, 4 colours
    surface = GLOVE_PALETTE_RGB[[0, 1, 2, 3]][grain].astype(np.uint8)
    image[:, :260][frame.labels[:, :260] == 0] = surface[frame.labels[:, :260] == 0]
    ys, xs = np.nonzero(frame.labels)
    centre = np.array([xs.mean(), ys.mean()])
    found = GloveSegmenter(calibration).process(image)
    assert found.hand_found
    assert np.hypot(*(np.array(found.crop.center_xy) - centre)) < 0.25 * found.crop.half_size
    off = GloveSegmenter(calibration, diversity_window=0, max_patch_fraction=0.0,
                         scene_colour_min_share=0.0).process(image)
    assert (not off.hand_found or np.hypot(*(np.array(off.crop.center_xy) - centre))
            > 0.25 * off.crop.half_size)



def _glove_beside_a_surface() -> tuple[synth.SyntheticFrame, np.ndarray]:
    """A rendered glove and its image with a plain orange surface touching its side."""
    frame = _rendered_glove((0.0, 0.0, 0.6))
    ys, xs = np.nonzero(frame.labels)
    image = frame.image_rgb.copy()
    x0 = int(np.percentile(xs, 60))
    surface = np.zeros(frame.labels.shape, bool)
    surface[ys.min():ys.max(), x0:min(x0 + 2 * (xs.max() - xs.min()), 639)] = True
    surface &= frame.labels == 0
    image[surface] = GLOVE_PALETTE_RGB[6]
    return frame, image


def test_an_orange_surface_touching_the_glove_is_shed_with_the_setting(calibration) -> None:
    """A rendered glove with a plain orange surface (a petal, a sleeve) touching its side:
    with ``max_patch_window_share`` the crop stays on the hand; off (the default) the surface
    joins the glove's region and pulls the crop towards it."""
    frame, image = _glove_beside_a_surface()
    ys, xs = np.nonzero(frame.labels)
    centre = np.array([xs.mean(), ys.mean()])
    on = GloveSegmenter(calibration, max_patch_window_share=0.15).process(image)
    off = GloveSegmenter(calibration).process(image)
    assert on.hand_found
    on_error = np.hypot(*(np.array(on.crop.center_xy) - centre))
    assert on_error < 0.25 * on.crop.half_size
    assert (not off.hand_found
            or np.hypot(*(np.array(off.crop.center_xy) - centre)) > on_error + 10.0)


def test_an_orange_surface_touching_the_glove_is_trimmed_with_junction_reach(calibration
                                                                           ) -> None:
    """The same rendered glove and touching orange surface: with ``junction_reach`` the crop
    keeps about the size it has without the surface; off (0) the surface's pixels join the
    glove and the crop grows. On the glove alone the setting changes nothing."""
    frame, image = _glove_beside_a_surface()
    plain = GloveSegmenter(calibration).process(frame.image_rgb)
    plain_on = GloveSegmenter(calibration, junction_reach=0.35).process(frame.image_rgb)
    assert plain.hand_found and plain_on.hand_found
    assert plain_on.crop.half_size == pytest.approx(plain.crop.half_size, rel=0.02)
    on = GloveSegmenter(calibration, junction_reach=0.35).process(image)
    off = GloveSegmenter(calibration).process(image)
    assert on.hand_found
    assert on.crop.half_size < 1.2 * plain.crop.half_size
    assert not off.hand_found or off.crop.half_size > 1.3 * plain.crop.half_size


#: The junction trim of issue 14's tenth pass (docs/RESULTS.md), ungated.
JUNCTION_TRIM = {'junction_reach': 0.35, 'junction_min_share': 0.05,
                 'junction_surfaces_only': 1}


def test_a_petal_smaller_than_the_palm_patch_is_trimmed_to_the_junctions(calibration) -> None:
    """A rendered glove with an orange petal touching its side, smaller than the glove's
    largest patch at the hand's scale: with the junction trim (``JUNCTION_TRIM``, and with
    the shipped config's, which is it with the gates) the crop keeps about the size it has
    without the petal; off (the class defaults) the petal joins the glove and the crop grows.
    On the glove alone the trim changes nothing."""
    from colorglove_ros.core.segmentation.color_model import read_calibration_config

    shipped = read_calibration_config('config/color_calibration.yaml')['segmenter']
    assert {name: shipped[name] for name in JUNCTION_TRIM} == JUNCTION_TRIM
    frame = _rendered_glove((0.0, 0.0, 0.6))
    plain = GloveSegmenter(calibration).process(frame.image_rgb)
    plain_on = GloveSegmenter(calibration, **JUNCTION_TRIM).process(frame.image_rgb)
    assert plain.hand_found and plain_on.hand_found
    assert plain_on.crop.half_size == pytest.approx(plain.crop.half_size, rel=0.02)
    ys, xs = np.nonzero(frame.labels)
    k = int(np.argmax(xs))
    side = int(np.sqrt(0.14) * 2.0 * plain.crop.half_size)   # under 0.15 of the crop window
    petal = np.zeros(frame.labels.shape, bool)
    petal[ys[k] - side // 2:ys[k] + side // 2, xs[k] - 6:xs[k] - 6 + side] = True
    image = frame.image_rgb.copy()
    image[petal & (frame.labels == 0)] = GLOVE_PALETTE_RGB[6]
    off = GloveSegmenter(calibration).process(image)
    assert off.crop.half_size > 1.12 * plain.crop.half_size
    for trim in (JUNCTION_TRIM, _gated_trim()):     # the gates let this trim through
        on = GloveSegmenter(calibration, **trim).process(image)
        assert on.hand_found and on.crop.half_size < 1.03 * plain.crop.half_size


def _gated_trim() -> dict[str, float]:
    """``JUNCTION_TRIM`` with the shipped config's gates (``junction_min_pull``,
    ``junction_max_window_kept``)."""
    from colorglove_ros.core.segmentation.color_model import read_calibration_config

    shipped = read_calibration_config('config/color_calibration.yaml')['segmenter']
    gates = {name: shipped[name] for name in ('junction_min_pull', 'junction_max_window_kept')}
    assert all(value > 0 for value in gates.values())
    return {**JUNCTION_TRIM, **gates}


@pytest.mark.parametrize('seed', [3, 12])
def test_the_gated_trim_leaves_a_glove_without_clutter_whole(calibration, seed: int) -> None:
    """Rendered gloves alone whose silhouette patches the ungated trim (``JUNCTION_TRIM``)
    cuts back (glove pixels lost, the crop shrunk): with the shipped gates
    (:func:`_gated_trim`) the label image and the observation are the trim-off ones, pixel
    for pixel."""
    image = _rendered_glove((0.0, 0.0, 0.6), seed).image_rgb
    off, cut, gated = (GloveSegmenter(calibration, **settings).process(image, keep_labels=True)
                       for settings in ({}, JUNCTION_TRIM, _gated_trim()))
    assert off.hand_found and gated.hand_found
    assert np.count_nonzero((off.label_image > 0) & (cut.label_image == 0)) > 500
    assert cut.crop.half_size < off.crop.half_size
    assert np.array_equal(gated.label_image, off.label_image)
    assert gated.crop == off.crop and np.array_equal(gated.tiny_labels, off.tiny_labels)


def _glove_with_a_red_sleeve() -> tuple[np.ndarray, np.ndarray]:
    """A rendered glove in the middle of the image with a red sleeve (glove red to the
    colour model) running off the image's bottom, and the same frame with a grey sleeve."""
    from colorglove_ros.core.synthetic.conditions import SLEEVE_ALBEDOS

    camera = synth.default_camera()
    q = synth.sample_pose(np.random.default_rng(4), camera, out_of_frame_prob=0.0)
    q[0:3] = [0.0, 0.0, 0.6]
    red, grey = (synth.render_frame(q, camera, np.random.default_rng(5),
                                    FrameConditions(sleeve_rgb=SLEEVE_ALBEDOS[name]))
                 for name in ('red', 'grey'))
    assert not red.labels[-1].any() and red.labels.any()     # the glove is whole in view
    return red.image_rgb, grey.image_rgb


def test_a_red_sleeve_running_off_the_image_does_not_cut_the_hand(calibration) -> None:
    """A red sleeve joined to the glove and running off the image: off (the class default)
    it pulls the crop down the forearm and makes the hand look cut by the border; with
    ``sleeve_reach`` (the shipped config's) the crop keeps about the size it has with a grey
    sleeve and the hand is not cut. With the grey sleeve the setting changes nothing."""
    from colorglove_ros.core.segmentation.color_model import read_calibration_config

    reach = read_calibration_config('config/color_calibration.yaml')['segmenter'][
        'sleeve_reach']
    red, grey = _glove_with_a_red_sleeve()
    plain = GloveSegmenter(calibration).process(grey)
    plain_on = GloveSegmenter(calibration, sleeve_reach=reach).process(grey)
    assert plain.hand_found and not plain.cut_by_border
    assert plain_on.crop.half_size == plain.crop.half_size
    off = GloveSegmenter(calibration).process(red)
    on = GloveSegmenter(calibration, sleeve_reach=reach).process(red)
    assert off.cut_by_border and off.crop.half_size > 2.0 * plain.crop.half_size
    assert on.hand_found and not on.cut_by_border
    assert on.crop.half_size < 1.5 * plain.crop.half_size


def test_a_short_red_sleeve_near_the_border_does_not_cut_the_hand(calibration) -> None:
    """The glove whole in view with its wrist 45 px above the image's bottom: the red
    sleeve's visible piece, joined to the glove's red wrist patch, is smaller than the
    largest printed patch, so with ``sleeve_min_share`` at that patch (the class default) it
    is kept and the hand looks cut by the border with a crop pulled down the forearm; with
    the shipped ``sleeve_min_share`` it is cut back, the hand is not cut and the crop is the
    one the glove has higher up."""
    from colorglove_ros.core.segmentation.color_model import read_calibration_config
    from colorglove_ros.core.synthetic.conditions import SLEEVE_ALBEDOS

    shipped = read_calibration_config('config/color_calibration.yaml')['segmenter']
    camera = synth.default_camera()
    q = synth.sample_pose(np.random.default_rng(4), camera, out_of_frame_prob=0.0)
    crops = []
    for y in (0.12, 0.18):
        q[0:3] = [0.0, y, 0.6]
        red = synth.render_frame(q, camera, np.random.default_rng(5),
                                 FrameConditions(sleeve_rgb=SLEEVE_ALBEDOS['red']))
        assert not red.labels[-1].any() and red.labels.any()   # the glove is whole in view
        seen = [GloveSegmenter(calibration, sleeve_reach=shipped['sleeve_reach'],
                               sleeve_min_share=share).process(red.image_rgb)
                for share in (LARGEST_PATCH_WINDOW_SHARE, shipped['sleeve_min_share'])]
        assert all(o.hand_found for o in seen)
        crops.append([o.crop.half_size for o in seen])
    old, new = seen
    assert shipped['sleeve_min_share'] < LARGEST_PATCH_WINDOW_SHARE
    assert old.cut_by_border and not new.cut_by_border
    assert old.crop.half_size > 1.3 * new.crop.half_size
    assert abs(new.crop.half_size - crops[0][1]) < 0.1 * crops[0][1]


def test_a_glove_really_cut_by_the_border_stays_cut_with_sleeve_reach(calibration) -> None:
    """The same glove moved down until a third of it is outside the image: cut by the
    border with ``sleeve_reach`` and the shipped ``sleeve_min_share`` as without (its own
    patches run off the image)."""
    from colorglove_ros.core.segmentation.color_model import read_calibration_config

    _, grey = _glove_with_a_red_sleeve()
    plain = GloveSegmenter(calibration).process(grey, keep_labels=True)
    ys = np.nonzero(plain.label_image)[0]
    shift = 480 - int(ys.max()) + int(0.3 * (ys.max() - ys.min()))
    image = np.concatenate([np.repeat(grey[:1], shift, 0), grey[:480 - shift]])
    for segmenter in (GloveSegmenter(calibration),
                      GloveSegmenter(calibration, sleeve_reach=0.1),
                      GloveSegmenter(calibration, sleeve_reach=0.1,
                                     sleeve_min_share=read_calibration_config(
                                         'config/color_calibration.yaml')['segmenter'][
                                         'sleeve_min_share'])):
        seen = segmenter.process(image)
        assert seen.hand_found and seen.cut_by_border


def _neighbourly_patchwork(adjacency: np.ndarray) -> np.ndarray:
    """A 3 x 3 block of 8-pixel patches whose every two side-by-side patches are colours
    ``adjacency`` lets border each other (a search over the glove's colours)."""
    colours = range(1, adjacency.shape[0])

    def fill(cells: list[int]) -> list[int] | None:
        k = len(cells)
        if k == 9:
            return cells
        for c in colours:
            if c in cells or (k % 3 and not adjacency[c, cells[k - 1]]) or (
                    k >= 3 and not adjacency[c, cells[k - 3]]):
                continue
            done = fill([*cells, c])
            if done:
                return done
        return None

    cells = fill([])
    assert cells is not None
    return np.kron(np.array(cells, np.uint8).reshape(3, 3), np.ones((8, 8), np.uint8))


def test_unsupported_regions_drop_clutter_whose_colours_the_glove_never_joins() -> None:
    """A patchwork of colours that border each other on the glove stays whole; beside it,
    and touching it, stripes of orange between red and pink (pairs the standard glove never
    joins, as on skin or petals) are dropped; with ``min_share`` 0 nothing is."""
    adjacency = default_colour_adjacency()
    red, orange, pink = 1, 7, 9
    assert not adjacency[orange, red] and not adjacency[orange, pink]
    labels = np.zeros((40, 70), np.uint8)
    labels[4:28, 4:28] = _neighbourly_patchwork(adjacency)
    for k, colour in enumerate((red, orange, pink, orange, red, orange)):
        labels[4:28, 28 + 4 * k:32 + 4 * k] = colour          # touching the patchwork
    drop = unsupported_regions(labels, adjacency, 0.1)
    assert not drop[4:28, 4:28].any()
    assert drop[4:28, 32:36].all() and drop[4:28, 40:44].all()    # the orange stripes
    assert not unsupported_regions(labels, adjacency, 0.0).any()
    lone = np.zeros_like(labels)
    lone[10:20, 10:20] = orange                             # no glove colour beside it
    assert unsupported_regions(lone, adjacency, 0.1)[10:20, 10:20].all()


def _with_face_like_stripes(frame: synth.SyntheticFrame) -> np.ndarray:
    """``frame``'s image with stripes of red, orange and pink (a face, petals) beside and
    touching the glove's right side."""
    ys, xs = np.nonzero(frame.labels)
    image = frame.image_rgb.copy()
    x0, y0 = int(xs.max()) - 4, int(np.median(ys)) - 30
    for k, colour in enumerate((1, 7, 9, 7, 1, 7, 9, 7)):     # red, orange, pink stripes
        stripe = np.zeros(frame.labels.shape, bool)
        stripe[y0:y0 + 60, x0 + 7 * k:x0 + 7 * k + 7] = True
        image[stripe & (frame.labels == 0)] = GLOVE_PALETTE_RGB[colour - 1]
    return image


def test_a_face_like_clutter_beside_the_glove_is_dropped_with_glove_contact_share(
        calibration) -> None:
    """A rendered glove with stripes of red, orange and pink beside it (a face, petals):
    off (the default) they join the glove's crop, which grows; with ``glove_contact_share``
    0.1 (the issue-14 sixteenth pass's setting) the crop keeps about the size it has without
    them. On the glove alone the setting moves the crop by at most a few per cent."""
    share = 0.1
    frame = _rendered_glove((0.0, 0.0, 0.6))
    plain = GloveSegmenter(calibration).process(frame.image_rgb)
    plain_on = GloveSegmenter(calibration, glove_contact_share=share).process(frame.image_rgb)
    assert plain.hand_found and plain_on.hand_found
    assert plain_on.crop.half_size == pytest.approx(plain.crop.half_size, rel=0.03)
    image = _with_face_like_stripes(frame)
    off = GloveSegmenter(calibration).process(image)
    on = GloveSegmenter(calibration, glove_contact_share=share).process(image)
    assert off.crop.half_size > 1.12 * plain.crop.half_size
    assert on.hand_found and on.crop.half_size < 1.05 * plain.crop.half_size


def test_unsupported_regions_take_labels_above_the_glove_colours_as_background() -> None:
    """A label image with values past the adjacency's colours (255, as an unclassified
    marker): those pixels count as background, as ``colour_components`` takes them, and
    nothing past the adjacency table is read."""
    adjacency = default_colour_adjacency()
    labels = np.zeros((40, 70), np.uint8)
    labels[4:28, 4:28] = _neighbourly_patchwork(adjacency)
    labels[4:28, 28:36] = 7                                  # orange beside the patchwork
    marked = labels.copy()
    marked[30:38, 4:60] = 255
    marked[4:28, 36:40] = adjacency.shape[0]                 # the first label past the table
    assert np.array_equal(unsupported_regions(marked, adjacency, 0.1),
                          unsupported_regions(labels, adjacency, 0.1))


def test_the_contact_filter_turned_on_after_construction_runs(calibration) -> None:
    """``glove_contact_share`` is a public setting: set on a segmenter built without it, the
    filter drops the face-like stripes as one built with it does."""
    image = _with_face_like_stripes(_rendered_glove((0.0, 0.0, 0.6)))
    built_on = GloveSegmenter(calibration, glove_contact_share=0.1).process(image)
    later = GloveSegmenter(calibration)
    later.glove_contact_share = 0.1
    turned_on = later.process(image)
    assert turned_on.hand_found and turned_on.crop == built_on.crop
    assert turned_on.blobs == built_on.blobs


#: The sixteenth pass's contact filter with the frame gate of the issue-14 eighteenth pass.
GATED_CONTACTS = {'glove_contact_share': 0.1, 'glove_contact_min_drop': 0.05}


@pytest.mark.parametrize('seed', [1, 4])
def test_the_gated_contact_filter_leaves_a_glove_without_clutter_whole(calibration,
                                                                     seed: int) -> None:
    """Rendered gloves alone one of whose silhouette patches meets only colours the glove
    never joins to it (a finger over the palm): the ungated filter drops it (glove pixels
    lost); with ``glove_contact_min_drop`` (the few pixels it would drop are under that share
    of the glove's) the label image and the observation are the filter-off ones."""
    image = _rendered_glove((0.0, 0.0, 0.6), seed).image_rgb
    off, cut, gated = (GloveSegmenter(calibration, **settings).process(image, keep_labels=True)
                       for settings in ({}, {'glove_contact_share': 0.1}, GATED_CONTACTS))
    assert off.hand_found and gated.hand_found
    assert np.count_nonzero((off.label_image > 0) & (cut.label_image == 0)) > 150
    assert np.array_equal(gated.label_image, off.label_image)
    assert gated.crop == off.crop and np.array_equal(gated.tiny_labels, off.tiny_labels)
    assert gated.blobs == off.blobs


def test_the_gated_contact_filter_still_drops_face_like_clutter(calibration) -> None:
    """The face-like stripes beside a rendered glove (as above) are many pixels the filter
    drops: with the gate (``GATED_CONTACTS``) they go as without it."""
    frame = _rendered_glove((0.0, 0.0, 0.6))
    plain = GloveSegmenter(calibration).process(frame.image_rgb)
    image = _with_face_like_stripes(frame)
    ungated = GloveSegmenter(calibration, glove_contact_share=0.1).process(image)
    gated = GloveSegmenter(calibration, **GATED_CONTACTS).process(image)
    assert GloveSegmenter(calibration).process(image).crop.half_size > 1.12 * plain.crop.half_size
    assert gated.hand_found and gated.crop == ungated.crop
    assert gated.crop.half_size < 1.05 * plain.crop.half_size


def _shipped_contact_settings() -> dict[str, float]:
    """The contact filter's settings in the shipped ``config/color_calibration.yaml``."""
    from scene_samples import segmenter_settings

    return {name: value for name, value in segmenter_settings().items()
            if name.startswith('glove_contact')}


def test_the_shipped_contact_filter_drops_face_like_clutter(calibration) -> None:
    """With the shipped config's contact-filter settings (on, gated by
    ``glove_contact_min_drop``) the face-like stripes beside a rendered glove no longer pull
    its crop: it keeps about the size it has without them."""
    frame = _rendered_glove((0.0, 0.0, 0.6))
    plain = GloveSegmenter(calibration).process(frame.image_rgb)
    image = _with_face_like_stripes(frame)
    shipped = GloveSegmenter(calibration, **_shipped_contact_settings()).process(image)
    assert GloveSegmenter(calibration).process(image).crop.half_size > 1.12 * plain.crop.half_size
    assert shipped.hand_found and shipped.crop.half_size < 1.05 * plain.crop.half_size


@pytest.mark.parametrize('seed', [1, 4])
def test_the_shipped_contact_filter_leaves_a_glove_without_clutter_whole(calibration,
                                                                       seed: int) -> None:
    """The rendered gloves whose silhouette patch the ungated filter drops (as above): with
    the shipped settings their label image and observation are the filter-off ones."""
    image = _rendered_glove((0.0, 0.0, 0.6), seed).image_rgb
    off, shipped = (GloveSegmenter(calibration, **settings).process(image, keep_labels=True)
                    for settings in ({}, _shipped_contact_settings()))
    assert _shipped_contact_settings()['glove_contact_share'] > 0
    assert np.array_equal(shipped.label_image, off.label_image)
    assert shipped.crop == off.crop and shipped.blobs == off.blobs
