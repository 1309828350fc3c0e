"""Features of the tracker's observation (tiny label image and blobs) and the letter
classifier that adds an image classifier's log-probabilities to the pose's."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pose_samples import MODEL, allowed_fingers
from scipy.spatial.transform import Rotation

from colorglove_ros.core.hand.observation_features import (
    GRID,
    OBSERVATION_FEATURES,
    OBSERVATION_UPRIGHT_FEATURES,
    RECORD_FIELDS,
    ObservationError,
    empty_observation_record,
    feature_set_features,
    image_angle,
    num_observation_features,
    observation_features,
    record_features,
)
from colorglove_ros.core.hand.pose_classifier import (
    load_pose_classifier,
    save_pose_classifier,
    train_pose_classifier,
)
from colorglove_ros.core.hand.poses import LETTER_SHAPES
from colorglove_ros.core.hand.spelling import (
    LETTERS,
    LetterClassifier,
    Speller,
    SpellingConfig,
    SpellingError,
    letter_rotation,
)


def _frame(thumb_x: int, scale: int = 1) -> dict[str, np.ndarray]:
    """One observation: a glove of colour 1 with a colour-6 'thumb' patch at column
    ``thumb_x`` (tiny pixels of a glove ``scale`` times the base size)."""
    record = empty_observation_record(1)
    tiny = record['tiny_labels'][0]
    tiny[10:10 + 12 * scale, 10:10 + 12 * scale] = 1
    tiny[10:10 + 3 * scale, thumb_x:thumb_x + 3 * scale] = 6
    record['blob_color'][0, :2] = [1, 6]
    record['blob_tiny_xy'][0, :2] = [[10 + 6 * scale, 10 + 6 * scale],
                                     [thumb_x + 1.5 * scale, 10 + 1.5 * scale]]
    record['blob_tiny_pixels'][0, :2] = [135.0 * scale ** 2, 9.0 * scale ** 2]
    return record


def test_the_features_place_each_colour_in_the_gloves_own_frame() -> None:
    left, right = record_features(_frame(10)), record_features(_frame(19))
    assert left.shape == right.shape == (1, num_observation_features())
    blobs = left[0, 10 * GRID * GRID:].reshape(10, 2, 4)
    assert tuple(blobs[5, 0, :2]) == (1.0, pytest.approx(9.0 / 144.0))
    assert not blobs[5, 1].any() and not blobs[2].any()        # no second patch, no blue
    moved = right[0, 10 * GRID * GRID:].reshape(10, 2, 4)
    assert moved[5, 0, 2] > blobs[5, 0, 2] + 0.5                # the thumb patch to the right
    # a larger glove, the same layout: the same blob placement (scale-free)
    big = record_features(_frame(10, scale=2))[0, 10 * GRID * GRID:].reshape(10, 2, 4)
    np.testing.assert_allclose(big[5, 0, 1:], blobs[5, 0, 1:], atol=0.08)
    with pytest.raises(ObservationError, match='lacks'):
        record_features({k: v for k, v in _frame(10).items() if k != RECORD_FIELDS[1]})
    with pytest.raises(ObservationError):
        observation_features(np.zeros((2, 40, 40)), np.zeros((1, 3)), np.zeros((1, 3, 2)),
                             np.zeros((1, 3)))


def _image_classifier() -> object:
    """An image classifier of 'tiny_observation' features that reads each letter from one
    feature column (column k high: letter k)."""
    rng = np.random.default_rng(0)
    n = num_observation_features()
    x = rng.normal(0.0, 0.1, (26 * 20, n))
    y = np.repeat(np.array(LETTERS), 20)
    for k in range(26):
        x[y == LETTERS[k], k] += 3.0
    return train_pose_classifier(x, y, OBSERVATION_FEATURES, kind='lda')


def test_the_image_classifier_adds_its_weighted_log_probabilities(tmp_path: Path) -> None:
    """With an image classifier, each frame's letter log-probabilities are the pose's plus
    image_weight times the image's: an M pose whose image says S reads as S when the image
    weighs enough; the file round trip keeps the feature set; a frame without its observation
    is read from the pose alone; a pose classifier in the image one's place is refused."""
    image = load_pose_classifier(save_pose_classifier(tmp_path / 'img.npz', _image_classifier()),
                                 OBSERVATION_FEATURES)
    q = MODEL.rest_pose()
    q[3:6] = letter_rotation('M')
    q[6:] = allowed_fingers(LETTER_SHAPES['M'])
    says_s = np.zeros(num_observation_features())
    says_s[LETTERS.index('S')] = 3.0
    pose_only = LetterClassifier(model=MODEL)
    assert LETTERS[int(np.argmax(pose_only.log_likelihoods(q)))] == 'M'
    for weight, expected in ((0.0, 'M'), (20.0, 'S')):
        both = LetterClassifier(SpellingConfig(image_weight=weight), MODEL,
                                image_classifier=image)
        got = both.log_likelihoods(q, says_s)
        image_part = image.log_proba(says_s)[[image.classes.index(k) for k in LETTERS]]
        np.testing.assert_allclose(got, pose_only.log_likelihoods(q) + weight * image_part)
        assert LETTERS[int(np.argmax(got))] == expected
    speller = Speller(SpellingConfig(image_weight=20.0), MODEL, image_classifier=image)
    frames = [speller.update(q, k / 30.0, says_s) for k in range(20)]
    assert [x for x in frames if x] == ['S']
    np.testing.assert_allclose(both.log_likelihoods(q), pose_only.log_likelihoods(q))
    with pytest.raises(SpellingError, match='observations'):
        both.log_likelihoods_batch(q[None], np.zeros((2, num_observation_features())))
    with pytest.raises(SpellingError, match='tiny_observation'):
        LetterClassifier(model=MODEL, image_classifier=load_pose_classifier(
            save_pose_classifier(tmp_path / 'pose.npz', train_pose_classifier(
                np.eye(26).repeat(3, axis=0), np.repeat(np.array(LETTERS), 3),
                'hand_shape_direction', kind='lda'))))
    with pytest.raises(SpellingError):
        SpellingConfig(image_weight=-0.1)


def test_the_shipped_image_classifier_reads_the_26_letters_from_the_observation() -> None:
    """config/letter_image_classifier.npz (the spelling node's and eval_spelling --tracker's
    default) classifies tiny_observation features into the 26 letters."""
    from colorglove_ros.core.hand.spelling import DEFAULT_LETTER_IMAGE_CLASSIFIER
    from colorglove_ros.paths import share_dir

    clf = load_pose_classifier(share_dir() / DEFAULT_LETTER_IMAGE_CLASSIFIER,
                               OBSERVATION_FEATURES)
    assert set(clf.classes) == set(LETTERS) and clf.mean.shape == (num_observation_features(),)
    assert '--what letter_images' in clf.source
    LetterClassifier(model=MODEL, image_classifier=clf)


def test_the_colour_maps_are_each_cells_share_of_each_colour() -> None:
    """The per-colour map against a pixel-by-pixel count: each grid cell's pixels of each glove
    colour over the cell's pixels, frame by frame; labels outside 1..10 count nowhere."""
    from colorglove_ros.core.conventions import NUM_COLORS
    from colorglove_ros.core.hand.observation_features import _colour_maps

    rng = np.random.default_rng(3)
    tiny = rng.integers(0, NUM_COLORS + 4, (5, 40, 40)).astype(np.uint8)
    expected = np.zeros((5, NUM_COLORS, GRID, GRID))
    cell_pixels = np.zeros((GRID, GRID))
    for y in range(40):
        for x in range(40):
            row, col = min(y * GRID // 40, GRID - 1), min(x * GRID // 40, GRID - 1)
            cell_pixels[row, col] += 1
            for i in range(5):
                if 1 <= tiny[i, y, x] <= NUM_COLORS:
                    expected[i, tiny[i, y, x] - 1, row, col] += 1
    expected /= cell_pixels
    got = _colour_maps(tiny)
    assert got.shape == (5, NUM_COLORS * GRID * GRID)
    assert np.allclose(got, expected.reshape(5, -1), rtol=0, atol=1e-12)


def _turned(record: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The observation seen a quarter turn about the camera's axis: tiny pixel (x, y) moves to
    (39 - y, x) (the image's x axis towards its y axis)."""
    turned = {k: v.copy() for k, v in record.items()}
    turned['tiny_labels'] = np.rot90(record['tiny_labels'], k=-1, axes=(1, 2)).copy()
    xy = record['blob_tiny_xy']
    turned['blob_tiny_xy'] = np.stack([39.0 - xy[..., 1], xy[..., 0]], axis=-1)
    return turned


def test_the_upright_features_take_the_in_plane_angle_out() -> None:
    record = _frame(10)
    rotvec = np.array([[0.3, -0.2, 0.1]])
    # the same hand turned a quarter about the camera's z axis, seen turned
    quarter = Rotation.from_rotvec([0.0, 0.0, np.pi / 2]) * Rotation.from_rotvec(rotvec[0])
    turned, turned_rotvec = _turned(record), quarter.as_rotvec()[None]
    assert image_angle(turned_rotvec)[0] == pytest.approx(image_angle(rotvec)[0] + np.pi / 2)
    upright = feature_set_features(record, OBSERVATION_UPRIGHT_FEATURES, rotvec)
    np.testing.assert_allclose(
        feature_set_features(turned, OBSERVATION_UPRIGHT_FEATURES, turned_rotvec), upright,
        atol=1e-9)
    # the plain features move with the view; the upright ones are another set of the same size
    plain, plain_turned = record_features(record), record_features(turned)
    assert np.abs(plain - plain_turned).max() > 0.5
    assert upright.shape == plain.shape
    np.testing.assert_array_equal(feature_set_features(record, OBSERVATION_FEATURES), plain)
    # the upright map holds each colour's share of the glove's pixels
    assert upright[0, :10 * GRID * GRID].sum() == pytest.approx(1.0)
    with pytest.raises(ObservationError, match='global rotations'):
        feature_set_features(record, OBSERVATION_UPRIGHT_FEATURES)
    with pytest.raises(ObservationError, match='unknown image feature set'):
        feature_set_features(record, 'hand_shape', rotvec)
    with pytest.raises(ObservationError, match='finite angle'):
        record_features(record, np.array([np.nan]))
