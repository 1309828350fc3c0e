"""Training samples of the hand classifiers: noise draws and the tracker's output."""
from __future__ import annotations

import numpy as np
import pytest
from pose_samples import MODEL

from colorglove_ros.core.evaluation.scripted_hands import (
    ScriptedSequence,
    TrackingNoise,
    script_poses,
)
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.pose_classifier import pose_features
from colorglove_ros.core.hand.spelling import LETTER_FEATURES
from colorglove_ros.tools import eval_spelling, train_hand_classifiers


class _HalfLostTracker:
    """Sees the true poses shifted by a constant on one joint, loses every other frame."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, int]] = []

    def observe(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                ) -> tuple[np.ndarray, np.ndarray]:
        self.calls.append((name, seed))
        seen = truth.poses.copy()
        seen[:, 6] += 0.2
        found = np.arange(len(seen)) % 2 == 0
        seen[~found] = np.nan
        return seen, found


def test_tracked_frames_are_added_repeated_and_lost_ones_left_out() -> None:
    segments = eval_spelling.spelling_script(MODEL, 1000, 1)[0]
    noise = TrackingNoise(0.0, 0.0)
    x, y = train_hand_classifiers.training_samples(MODEL, [(1000, segments)], noise, 1,
                                                   LETTER_FEATURES)
    tracker = _HalfLostTracker()
    x2, y2 = train_hand_classifiers.training_samples(
        MODEL, [(1000, segments)], noise, 1, LETTER_FEATURES, tracked=[(1001, segments)],
        tracker=tracker, name='spelling', repeats=3)
    assert tracker.calls == [('spelling', 1001)]
    truth = script_poses(segments)
    hold = truth.holding & (np.arange(len(truth.poses)) % 2 == 0)
    shifted = truth.poses[hold].copy()
    shifted[:, 6] += 0.2
    expected = pose_features(MODEL, shifted, LETTER_FEATURES)
    held = len(y)
    np.testing.assert_array_equal(y2[:held], y)
    assert len(y2) == held + 3 * len(expected)
    np.testing.assert_allclose(x2[held:], np.concatenate([expected] * 3))
    np.testing.assert_array_equal(y2[held:], np.concatenate([truth.label[hold]] * 3))
    with pytest.raises(ValueError, match='tracker'):
        train_hand_classifiers.training_samples(MODEL, [], noise, 1, LETTER_FEATURES,
                                                tracked=[(1001, segments)])


def test_tracker_seeds_must_be_training_seeds() -> None:
    assert train_hand_classifiers.main(['--what', 'letters', '--tracker-seeds', '100']) == 1


def test_the_quadratic_discriminant_is_trained_and_written(tmp_path) -> None:
    from colorglove_ros.core.hand.pose_classifier import load_pose_classifier

    output = tmp_path / 'letters.npz'
    assert train_hand_classifiers.main(['--what', 'letters', '--spelling-sequences', '2',
                                        '--words', '2', '--noise-draws', '1', '--model', 'qda',
                                        '--covariance-blend', '0.25',
                                        '--letter-output', str(output)]) == 0
    clf = load_pose_classifier(output, LETTER_FEATURES)
    assert clf.quadratic is not None and clf.quadratic.shape[0] == len(clf.classes) >= 3
    assert '--model qda' in clf.source and '--covariance-blend 0.25' in clf.source
