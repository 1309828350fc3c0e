"""The pose classifier: scale-free wrist-frame features, seeded training, the versioned file."""
from __future__ import annotations

import numpy as np
import pytest
from pose_samples import MODEL, hand_pose

from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.pose_classifier import (
    ClassifierError,
    load_pose_classifier,
    pose_features,
    save_pose_classifier,
    train_pose_classifier,
)
from colorglove_ros.core.hand.poses import GESTURE_SHAPES

SHAPES = ('fist', 'flat', 'point', 'pinch')


def _samples(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    poses, labels = [], []
    for _ in range(n):
        name = SHAPES[rng.integers(len(SHAPES))]
        fingers = GESTURE_SHAPES[name] + rng.normal(0.0, np.deg2rad(4.0), 20)
        poses.append(hand_pose(fingers))
        labels.append(name)
    return pose_features(MODEL, np.array(poses), 'hand_shape'), np.array(labels)


def test_features_are_in_the_wrist_frame_and_scale_free() -> None:
    q = hand_pose(GESTURE_SHAPES['pinch'])
    moved = q.copy()
    moved[0:6] = [0.1, -0.05, 0.7, 0.4, -0.3, 1.2]
    big = HandModel(hand_length_m=1.2 * MODEL.hand_length_m)
    np.testing.assert_allclose(pose_features(MODEL, q, 'hand_shape'),
                               pose_features(MODEL, moved, 'hand_shape'), atol=1e-9)
    np.testing.assert_allclose(pose_features(MODEL, q, 'hand_shape'),
                               pose_features(big, q, 'hand_shape'), atol=1e-9)
    with_direction = pose_features(MODEL, q, 'hand_shape_direction')
    assert with_direction.shape == (pose_features(MODEL, q, 'hand_shape').shape[0] + 3,)
    np.testing.assert_allclose(with_direction[-3:], [0.0, -1.0, 0.0], atol=1e-9)
    with pytest.raises(ClassifierError):
        pose_features(MODEL, q, 'colour')


def test_training_is_seeded_and_the_file_round_trips(tmp_path) -> None:
    x, y = _samples(np.random.default_rng(0), 400)
    test_x, test_y = _samples(np.random.default_rng(1), 200)
    clf = train_pose_classifier(x, y, 'hand_shape', hidden=16, seed=3, source='test')
    again = train_pose_classifier(x, y, 'hand_shape', hidden=16, seed=3)
    np.testing.assert_allclose(clf.log_proba(test_x), again.log_proba(test_x))
    predicted = np.asarray(clf.classes)[np.argmax(clf.log_proba(test_x), axis=1)]
    assert np.mean(predicted == test_y) > 0.95
    np.testing.assert_allclose(np.exp(clf.log_proba(test_x)).sum(axis=1), 1.0)
    path = save_pose_classifier(tmp_path / 'c.npz', clf)
    loaded = load_pose_classifier(path, 'hand_shape')
    assert loaded.classes == clf.classes and loaded.source == 'test'
    np.testing.assert_allclose(loaded.log_proba(test_x), clf.log_proba(test_x))
    q = hand_pose(GESTURE_SHAPES['fist'])
    assert loaded.classes[int(np.argmax(loaded.pose_log_proba(MODEL, q)))] == 'fist'
    with pytest.raises(ClassifierError, match='expected'):
        load_pose_classifier(path, 'hand_shape_direction')


def test_bad_files(tmp_path) -> None:
    with pytest.raises(ClassifierError, match='not found'):
        load_pose_classifier(tmp_path / 'missing.npz')
    x, y = _samples(np.random.default_rng(0), 120)
    clf = train_pose_classifier(x, y, 'hand_shape', hidden=4, seed=0)
    path = save_pose_classifier(tmp_path / 'c.npz', clf)
    data = dict(np.load(path))
    np.savez(tmp_path / 'old.npz', **{**data, 'version': np.array(0)})
    with pytest.raises(ClassifierError, match='version'):
        load_pose_classifier(tmp_path / 'old.npz')
    np.savez(tmp_path / 'cut.npz', **{**data, 'classes': np.array(['a', 'b'])})
    with pytest.raises(ClassifierError, match='inconsistent'):
        load_pose_classifier(tmp_path / 'cut.npz')
    (tmp_path / 'text.npz').write_text('not a zip')
    with pytest.raises(ClassifierError):
        load_pose_classifier(tmp_path / 'text.npz')


def test_linear_discriminant_is_one_layer_and_round_trips(tmp_path) -> None:
    x, y = _samples(np.random.default_rng(0), 400)
    test_x, test_y = _samples(np.random.default_rng(1), 200)
    clf = train_pose_classifier(x, y, 'hand_shape', kind='lda', source='lda test')
    assert len(clf.weights) == 1 and clf.weights[0].shape == (x.shape[1], len(clf.classes))
    predicted = np.asarray(clf.classes)[np.argmax(clf.log_proba(test_x), axis=1)]
    assert np.mean(predicted == test_y) > 0.95
    np.testing.assert_allclose(np.exp(clf.log_proba(test_x)).sum(axis=1), 1.0)
    loaded = load_pose_classifier(save_pose_classifier(tmp_path / 'l.npz', clf), 'hand_shape')
    np.testing.assert_allclose(loaded.log_proba(test_x), clf.log_proba(test_x))
    with pytest.raises(ClassifierError, match='kind'):
        train_pose_classifier(x, y, 'hand_shape', kind='forest')


def _spreads(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Three classes about the same centre told apart by their spread and its direction
    (no linear boundary separates them)."""
    labels = np.array(['narrow', 'wide_x', 'wide_y'])[rng.integers(3, size=n)]
    spread = {'narrow': (0.2, 0.2), 'wide_x': (3.0, 0.2), 'wide_y': (0.2, 3.0)}
    x = np.array([rng.normal(0.0, spread[k]) for k in labels])
    return np.column_stack([x, rng.normal(0.0, 1.0, (n, 2))]), labels


def test_quadratic_discriminant_holds_each_class_spread(tmp_path) -> None:
    x, y = _spreads(np.random.default_rng(0), 3000)
    test_x, test_y = _spreads(np.random.default_rng(1), 1000)

    def accuracy(clf) -> float:
        return float(np.mean(np.asarray(clf.classes)[np.argmax(clf.log_proba(test_x), 1)]
                             == test_y))

    lda = train_pose_classifier(x, y, 'hand_shape', kind='lda')
    qda = train_pose_classifier(x, y, 'hand_shape', kind='qda', covariance_blend=0.0,
                                source='qda test')
    assert accuracy(lda) < 0.6 and accuracy(qda) > 0.85
    assert qda.quadratic is not None and qda.quadratic.shape == (3, 4, 4)
    np.testing.assert_allclose(np.exp(qda.log_proba(test_x)).sum(axis=1), 1.0)
    np.testing.assert_allclose(qda.log_proba(test_x[0]), qda.log_proba(test_x[:1])[0])
    # all of the shared covariance is the linear discriminant
    shared = train_pose_classifier(x, y, 'hand_shape', kind='qda', covariance_blend=1.0)
    np.testing.assert_allclose(shared.log_proba(test_x), lda.log_proba(test_x), atol=1e-8)
    loaded = load_pose_classifier(save_pose_classifier(tmp_path / 'q.npz', qda), 'hand_shape')
    assert loaded.source == 'qda test'
    np.testing.assert_allclose(loaded.log_proba(test_x), qda.log_proba(test_x))
    with pytest.raises(ClassifierError, match='covariance_blend'):
        train_pose_classifier(x, y, 'hand_shape', kind='qda', covariance_blend=1.5)


def test_version_1_files_are_still_read_and_a_bad_quadratic_layer_is_refused(tmp_path) -> None:
    x, y = _samples(np.random.default_rng(0), 200)
    lda = train_pose_classifier(x, y, 'hand_shape', kind='lda')
    data = dict(np.load(save_pose_classifier(tmp_path / 'l.npz', lda)))
    assert int(data['version']) == 2 and data['quadratic'].size == 0
    del data['quadratic']
    np.savez(tmp_path / 'v1.npz', **{**data, 'version': np.array(1)})
    old = load_pose_classifier(tmp_path / 'v1.npz', 'hand_shape')
    assert old.quadratic is None
    np.testing.assert_allclose(old.log_proba(x), lda.log_proba(x))
    qda = train_pose_classifier(x, y, 'hand_shape', kind='qda')
    data = dict(np.load(save_pose_classifier(tmp_path / 'q.npz', qda)))
    np.savez(tmp_path / 'bad.npz', **{**data, 'quadratic': data['quadratic'][:, :-1]})
    with pytest.raises(ClassifierError, match='inconsistent'):
        load_pose_classifier(tmp_path / 'bad.npz')
