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


class _HoldRenderer:
    """Stands in for ScriptedTracker.hold_observations: every ``every``-th hold frame, its
    tiny image showing the frame's letter as one square of a colour and place of its own; and
    for the evaluation, the same observation of every frame (``observation``)."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, int, int]] = []

    @staticmethod
    def _record(truth: ScriptedSequence, frames: np.ndarray) -> dict[str, np.ndarray]:
        from colorglove_ros.core.hand.observation_features import empty_observation_record
        from colorglove_ros.core.hand.spelling import LETTERS

        record = empty_observation_record(len(frames))
        for j, i in enumerate(frames):
            k = LETTERS.index(truth.label[i])
            row = 8 * (k // 10)
            record['tiny_labels'][j, row:row + 8, :8] = 1 + k % 10
        return record

    def hold_observations(self, name: str, seed: int, truth: ScriptedSequence, every: int
                          ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        self.calls.append((name, seed, every))
        frames = np.concatenate([np.flatnonzero((truth.segment == k) & truth.holding)[::every]
                                 for k in np.unique(truth.segment)])
        return frames, self._record(truth, frames)

    def observe(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                ) -> tuple[np.ndarray, np.ndarray]:
        return truth.poses, np.ones(len(truth.poses), bool)

    def observation(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                    ) -> dict[str, np.ndarray]:
        return self._record(truth, np.arange(len(truth.poses)))


def test_the_letter_image_classifier_learns_from_rendered_hold_frames() -> None:
    """Image training samples are every ``every``-th hold frame's observation features with
    its letter; the classifier trained on them, combined with the templates by the spelling
    evaluation, reads the letters the image shows; the noise model (no observation) refuses
    an image classifier."""
    from colorglove_ros.core.evaluation.scripted_hands import Segment
    from colorglove_ros.core.hand.observation_features import (
        OBSERVATION_FEATURES,
        record_features,
    )
    from colorglove_ros.core.hand.pose_classifier import train_pose_classifier
    from colorglove_ros.core.hand.spelling import LETTERS

    renderer = _HoldRenderer()
    alphabet = [Segment(k, np.zeros(20), np.zeros(3), np.array([0.0, 0.05, 0.5]), 0.5, 0.2)
                for k in LETTERS]
    scripts = [(1200, eval_spelling.spelling_script(MODEL, 1200, 3)[0]), (1201, alphabet)]
    x, y = train_hand_classifiers.image_training_samples(MODEL, scripts, renderer, 4)
    assert renderer.calls == [('spelling', 1200, 4), ('spelling', 1201, 4)]
    truth = script_poses(scripts[0][1])
    frames = np.concatenate([np.flatnonzero((truth.segment == k) & truth.holding)[::4]
                             for k in np.unique(truth.segment)])
    np.testing.assert_array_equal(y[:len(frames)], truth.label[frames])
    np.testing.assert_allclose(x[:len(frames)],
                               record_features(renderer._record(truth, frames)))
    jitter = np.random.default_rng(0).normal(0.0, 0.01, x.shape)   # no class without spread
    image = train_pose_classifier(x + jitter, y, OBSERVATION_FEATURES, kind='lda')
    seeds = [1200, 1201]
    with_image = eval_spelling.evaluate(seeds, 3, renderer, None, image_classifier=image,
                                        image_weight=5.0)
    assert with_image['hold_letter_accuracy'] == with_image['letter_accuracy'] == 1.0
    with pytest.raises(eval_spelling.SpellingError, match='tracker'):
        eval_spelling.evaluate(seeds, 3, TrackingNoise(), None, image_classifier=image)


class _GestureRenderer(_HoldRenderer):
    """:class:`_HoldRenderer` on gesture scripts: every frame's pose is the flat hand (the
    pose classifier reads an open hand throughout) and its tiny image shows the frame's class
    (a gesture or none) as one square of a colour and place of its own."""

    def __init__(self) -> None:
        super().__init__()
        from colorglove_ros.core.hand.poses import GESTURE_SHAPES, full_pose

        self.flat = full_pose(MODEL, GESTURE_SHAPES['flat'])

    @staticmethod
    def _record(truth: ScriptedSequence, frames: np.ndarray) -> dict[str, np.ndarray]:
        from colorglove_ros.core.hand.gestures import GESTURE_NAMES
        from colorglove_ros.core.hand.observation_features import empty_observation_record

        record = empty_observation_record(len(frames))
        for j, i in enumerate(frames):
            k = (*GESTURE_NAMES, '').index(truth.label[i])
            record['tiny_labels'][j, 4 * k:4 * k + 8, :8] = 1 + k
        return record

    def observe(self, name: str, seed: int, truth: ScriptedSequence, model: HandModel
                ) -> tuple[np.ndarray, np.ndarray]:
        return np.tile(self.flat, (len(truth.poses), 1)), np.ones(len(truth.poses), bool)


@pytest.mark.slow
def test_the_gesture_image_classifier_learns_from_rendered_hold_frames() -> None:
    """Gesture image samples are the gesture scripts' hold frames (neutral ones labelled
    none); combined with the pose classifier by the gesture evaluation, the classifier trained
    on them finds the gestures the image shows where the pose says open hand throughout (the
    shape gate off: it refuses a pinch or a grab to an open hand whatever the image says);
    the noise model (no observation) refuses an image classifier."""
    from colorglove_ros.core.hand.gestures import (
        DEFAULT_GESTURE_CLASSIFIER,
        GESTURE_FEATURES,
        NO_GESTURE,
        GestureConfig,
        ShapeGate,
    )
    from colorglove_ros.core.hand.observation_features import OBSERVATION_FEATURES
    from colorglove_ros.core.hand.pose_classifier import (
        load_pose_classifier,
        train_pose_classifier,
    )
    from colorglove_ros.paths import share_dir
    from colorglove_ros.tools import eval_gestures

    renderer = _GestureRenderer()
    seeds = [1300, 1301]
    scripts = [(s, eval_gestures.gesture_script(MODEL, s, 12)) for s in seeds]
    x, y = train_hand_classifiers.image_training_samples(MODEL, scripts, renderer, 4,
                                                         'gestures')
    assert renderer.calls == [('gestures', 1300, 4), ('gestures', 1301, 4)]
    truth = script_poses(scripts[0][1])
    frames = np.concatenate([np.flatnonzero((truth.segment == k) & truth.holding)[::4]
                             for k in np.unique(truth.segment)])
    np.testing.assert_array_equal(y[:len(frames)],
                                  [c or NO_GESTURE for c in truth.label[frames]])
    jitter = np.random.default_rng(0).normal(0.0, 0.01, x.shape)
    image = train_pose_classifier(x + jitter, y, OBSERVATION_FEATURES, kind='lda')
    pose = load_pose_classifier(share_dir() / DEFAULT_GESTURE_CLASSIFIER, GESTURE_FEATURES)
    ungated = GestureConfig(shape=ShapeGate())
    alone = eval_gestures.evaluate(seeds, 12, renderer, pose, ungated)['rows'][-1]
    both = eval_gestures.evaluate(seeds, 12, renderer, pose, ungated, image_classifier=image,
                                  image_weight=5.0)['rows'][-1]
    assert alone['recall'] < 0.5
    assert both['precision'] == both['recall'] == both['hold_accuracy'] == 1.0
    with pytest.raises(eval_gestures.GestureError, match='tracker'):
        eval_gestures.evaluate(seeds, 12, TrackingNoise(), pose, image_classifier=image)
