"""Gesture scores on the collection's shapes, the detector's hysteresis, the event text, and
the evaluation on a noise-free scripted sequence."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from pose_samples import MODEL, hand_pose

from colorglove_ros.core.evaluation.scripted_hands import TrackingNoise
from colorglove_ros.core.hand.gestures import (
    DEFAULT_GESTURE_CLASSIFIER,
    GESTURE_FEATURES,
    NO_GESTURE,
    GestureConfig,
    GestureDetector,
    GestureError,
    GestureEvent,
    ShapeGate,
    format_event,
    gesture_features,
    gesture_scores,
    parse_event,
)
from colorglove_ros.core.hand.hysteresis import HoldConfig
from colorglove_ros.core.hand.pose_classifier import PoseClassifier, load_pose_classifier
from colorglove_ros.core.hand.poses import GESTURE_SHAPES, LETTER_SHAPES, full_pose
from colorglove_ros.core.hand.spelling import TRAINED_LETTER_CLASSIFIER
from colorglove_ros.paths import share_dir
from colorglove_ros.tools import eval_gestures


def _pose(shape: str) -> np.ndarray:
    return hand_pose(GESTURE_SHAPES[shape])


@pytest.mark.parametrize('shape, gesture', [
    ('fist', 'grab'), ('point', 'point'), ('flat', 'open_hand'), ('spread', 'open_hand'),
    ('pinch', 'pinch_index'), ('ok', 'pinch_index')])
def test_shape_scores(shape: str, gesture: str) -> None:
    scores = gesture_scores(gesture_features(MODEL, _pose(shape)))
    assert scores[gesture] > 0.85, scores
    assert all(s < 0.3 for name, s in scores.items() if name != gesture), scores


def test_neutral_shapes_score_no_gesture() -> None:
    for name in eval_gestures.NEUTRAL_SHAPES:
        scores = gesture_scores(gesture_features(MODEL, hand_pose(eval_gestures._SHAPES[name])))
        assert max(scores.values()) < 0.3, (name, scores)


def test_pinch_shapes_of_every_finger() -> None:
    rng = np.random.default_rng(0)
    for finger in ('index', 'middle', 'ring', 'little'):
        scores = gesture_scores(gesture_features(
            MODEL, full_pose(MODEL, eval_gestures.pinch_shape(MODEL, rng, finger))))
        assert max(scores, key=scores.get) == f'pinch_{finger}', scores


def test_hysteresis_and_loss() -> None:
    config = GestureConfig(hold=HoldConfig(smoothing=0.25, on_score=0.7, off_score=0.3,
                                           hold_on_s=2 / 30, hold_off_s=4 / 30))
    detector = GestureDetector(MODEL, config)
    flat, fist = _pose('flat'), _pose('fist')
    events = [e for k in range(10) for e in detector.update(flat, k / 30)]
    assert [(e.name, e.state) for e in events] == [('open_hand', 'start')]
    start = events[0].stamp
    # the smoothed score needs a frame or two to cross, then min_on_frames
    assert 2 / 30 - 1e-9 <= start <= 5 / 30 + 1e-9
    assert detector.active == ('open_hand',)
    # a single odd frame changes nothing
    assert detector.update(fist, 0.4) == []
    assert detector.active == ('open_hand',)
    events = [e for k in range(20) for e in detector.update(fist, 0.5 + k / 30)]
    assert sorted((e.name, e.state) for e in events) == [('grab', 'start'), ('open_hand', 'end')]
    assert detector.active == ('grab',)
    # a loss shorter than lose_after_s decides nothing: the grab goes on, not started again
    after = config.lose_after_s
    assert [e for k in range(3) for e in detector.update(None, 1.5 + k / 30)] == []
    assert [e for k in range(5) for e in detector.update(fist, 1.6 + k / 30)] == []
    assert detector.active == ('grab',)
    assert detector.update(None, 2.0) == []
    assert detector.update(None, 2.0 + after - 0.01) == []
    lost = detector.update(None, 2.0 + after)
    assert [(e.name, e.state, e.confidence) for e in lost] == [('grab', 'end', 0.0)]
    assert detector.active == ()
    assert detector.update(None, 3.0) == []
    at_once = GestureDetector(MODEL, replace(config, lose_after_s=0.0))
    for k in range(10):
        at_once.update(flat, k / 30)
    assert [e.state for e in at_once.update(None, 0.4)] == ['end']
    with pytest.raises(GestureError):
        GestureConfig(lose_after_s=-0.1)


def test_event_text_round_trip() -> None:
    event = GestureEvent('pinch_ring', 'start', 0.876)
    assert format_event(event) == 'pinch_ring:start:0.88'
    back = parse_event(format_event(event), stamp=3.0)
    assert (back.name, back.state, back.confidence, back.stamp) == ('pinch_ring', 'start',
                                                                    0.88, 3.0)
    for bad in ('wave:start:0.5', 'grab:begin:0.5', 'grab:start:x', 'grab:start:1.5', 'grab'):
        with pytest.raises(GestureError):
            parse_event(bad)
    with pytest.raises(GestureError):
        GestureConfig(extended=0.6, curled=0.5)


def _shipped() -> PoseClassifier:
    return load_pose_classifier(share_dir() / DEFAULT_GESTURE_CLASSIFIER, GESTURE_FEATURES)


@pytest.mark.parametrize('shape, gesture', [
    ('fist', 'grab'), ('point', 'point'), ('flat', 'open_hand'), ('spread', 'open_hand'),
    ('pinch', 'pinch_index'), ('relaxed', NO_GESTURE), ('letter_V', NO_GESTURE)])
def test_shipped_classifier_on_named_shapes(shape: str, gesture: str) -> None:
    classifier = _shipped()
    fingers = {**GESTURE_SHAPES, **{f'letter_{k}': v for k, v in LETTER_SHAPES.items()}}[shape]
    p = np.exp(classifier.pose_log_proba(MODEL, hand_pose(fingers)))
    assert classifier.classes[int(np.argmax(p))] == gesture


def test_detector_refuses_a_letter_classifier() -> None:
    letters = load_pose_classifier(share_dir() / TRAINED_LETTER_CLASSIFIER)
    with pytest.raises(GestureError):
        GestureDetector(MODEL, classifier=letters)


def test_evaluation_without_noise_is_perfect_and_with_noise_is_not() -> None:
    clean = eval_gestures.evaluate([7], episodes=16, source=TrackingNoise(0.0, 0.0),
                                   classifier=_shipped())
    overall = clean['rows'][-1]
    assert overall['episodes'] >= 8
    assert overall['precision'] == 1.0 and overall['recall'] == 1.0
    assert overall['hold_accuracy'] == 1.0 and clean['neutral_holds_as_gesture'] == 0.0
    assert clean['joint_mae_deg_realised'] == pytest.approx(0.0, abs=1e-12)
    noisy = eval_gestures.evaluate([7], episodes=16, source=TrackingNoise(25.0, 5.0),
                                   classifier=_shipped())
    assert noisy['joint_mae_deg_realised'] == pytest.approx(25.0, rel=0.02)
    assert min(noisy['rows'][-1]['precision'], noisy['rows'][-1]['recall']) < 0.95
    assert noisy['rows'][-1]['hold_accuracy'] < 1.0


def test_hold_accuracy_needs_a_classifier() -> None:
    rules = eval_gestures.evaluate([7], episodes=6, source=TrackingNoise(0.0, 0.0))
    assert all(np.isnan(row['hold_accuracy']) for row in rules['rows'])
    assert np.isnan(rules['neutral_holds_as_gesture'])


def test_frames_of_weak_evidence_decide_nothing() -> None:
    """With the evidence gate on, a hold whose frames matched too few constraints starts no
    gesture and does not end an active one (a skipped frame is not a lost hand); frames with
    unknown evidence count; with the gate off the evidence is ignored; the default gate
    is on."""
    from colorglove_ros.core.hand.frame_evidence import EvidenceGate, FrameEvidence

    hold = HoldConfig(smoothing=0.25, on_score=0.7, off_score=0.3, hold_on_s=2 / 30,
                      hold_off_s=4 / 30)
    weak = FrameEvidence(5.0, 2.0)
    flat, fist = _pose('flat'), _pose('fist')
    gated = GestureDetector(MODEL, GestureConfig(hold=hold, evidence=EvidenceGate(
        min_constraints=11)))
    assert [e for k in range(15) for e in gated.update(flat, k / 30, weak)] == []
    assert gated.active == ()
    started = [e for k in range(15) for e in gated.update(flat, 0.5 + k / 30, None)]
    assert [(e.name, e.state) for e in started] == [('open_hand', 'start')]
    assert [e for k in range(15) for e in gated.update(fist, 1.0 + k / 30, weak)] == []
    assert gated.active == ('open_hand',)
    lost = [e for k in range(12) for e in gated.update(None, 2.0 + k / 30, weak)]
    assert [e.state for e in lost] == ['end']      # still a loss
    assert GestureConfig().evidence.enabled
    plain = GestureDetector(MODEL, GestureConfig(hold=hold, evidence=EvidenceGate()))
    events = [e for k in range(15) for e in plain.update(flat, k / 30, weak)]
    assert [(e.name, e.state) for e in events] == [('open_hand', 'start')]


def _constant_classifier(gesture: str, probability: float) -> PoseClassifier:
    """A pose classifier (``hand_shape``) that gives every pose ``probability`` of
    ``gesture`` and the rest to the other classes alike."""
    from colorglove_ros.core.hand.gestures import GESTURE_NAMES
    from colorglove_ros.core.hand.pose_classifier import pose_features

    classes = (*GESTURE_NAMES, NO_GESTURE)
    rest = (1.0 - probability) / (len(classes) - 1)
    biases = np.log([probability if c == gesture else rest for c in classes])
    size = pose_features(MODEL, _pose('flat'), GESTURE_FEATURES).shape[0]
    return PoseClassifier(classes, GESTURE_FEATURES, np.zeros(size), np.ones(size),
                          (np.zeros((size, len(classes))),), (biases,))


@pytest.mark.parametrize('gesture, refused, kept', [
    ('pinch_index', 'flat', 'pinch'), ('pinch_little', 'spread', None),
    ('grab', 'point', 'fist'), ('grab', 'flat', None), ('point', 'flat', 'point')])
def test_the_shape_gate_bounds_a_classifiers_pinch_and_grab(gesture: str, refused: str,
                                                            kept: str | None) -> None:
    """A classifier that calls every pose ``gesture`` starts it on a pose whose thumb tip is
    far from that fingertip (a pinch) or that has a straight finger where the gesture curls
    one (a grab, a point) only with the shape gate off; with the default gate the score there
    is near 0, and on a pose of the gesture (the collection's pinch, fist, point) the gate
    leaves the classifier's score nearly whole."""
    from colorglove_ros.core.hand.gestures import shape_gate_factors

    classifier = _constant_classifier(gesture, 0.9)
    hold = HoldConfig(smoothing=0.5, on_score=0.7, off_score=0.3, hold_on_s=0.0,
                      hold_off_s=0.1)

    def starts(shape: str, gate: ShapeGate | None) -> list[str]:
        config = GestureConfig(hold=hold) if gate is None else \
            GestureConfig(hold=hold, shape=gate)
        detector = GestureDetector(MODEL, config, classifier)
        return [e.name for k in range(10) for e in detector.update(_pose(shape), k / 30.0)
                if e.state == 'start']

    assert starts(refused, ShapeGate()) == [gesture]
    assert starts(refused, None) == []
    far = GestureDetector(MODEL, GestureConfig(), classifier).frame_scores(_pose(refused))
    assert far[gesture] < 0.05
    assert shape_gate_factors(gesture_features(MODEL, _pose(refused)))[gesture] < 0.05
    if kept is not None:
        assert starts(kept, None) == [gesture]
        near = GestureDetector(MODEL, GestureConfig(), classifier).frame_scores(_pose(kept))
        assert near[gesture] == pytest.approx(0.9, abs=0.05)


def test_the_shape_gate_settings() -> None:
    """The factors are 1 for the gestures the gate does not bound (open hand) and 1/2 at its
    bounds (a point's middle, ring and little curls, a grab's four); off
    by ShapeGate(), on by default; bad bounds refused."""
    from colorglove_ros.core.hand.gestures import GESTURE_NAMES, GestureFeatures, shape_gate_factors

    gate = ShapeGate(max_pinch_distance=0.3, min_curl=0.5)
    features = GestureFeatures(np.array([0.3, 0.0, 1.0, 0.3]), np.array([0.5, 0.9, 0.9, 0.9]))
    factors = shape_gate_factors(features, GestureConfig(shape=gate))
    assert factors['pinch_index'] == pytest.approx(0.5)
    assert factors['pinch_middle'] > 0.99 and factors['pinch_ring'] < 1e-6
    assert factors['grab'] == pytest.approx(0.5)
    assert factors['point'] > 0.99 and factors['open_hand'] == 1.0   # the index is not bound
    features = GestureFeatures(features.pinch_distance, np.array([0.0, 0.9, 0.5, 0.9]))
    factors = shape_gate_factors(features, GestureConfig(shape=gate))
    assert factors['point'] == pytest.approx(0.5) and factors['grab'] < 1e-4
    assert shape_gate_factors(features, GestureConfig(shape=ShapeGate())) == \
        dict.fromkeys(GESTURE_NAMES, 1.0)
    assert not ShapeGate().enabled and GestureConfig().shape.enabled
    for bad in ({'max_pinch_distance': 0.0}, {'max_pinch_distance': -1.0},
                {'min_curl': 1.5}, {'min_curl': -0.1},
                {'max_pinch_distance': float('nan')}):
        with pytest.raises(GestureError):
            ShapeGate(**bad)


def _gesture_image_classifier(feature_set: str = 'tiny_observation') -> PoseClassifier:
    """A classifier of ``feature_set`` features (an image set) that reads each gesture class
    (and none) from one feature column (column k high: class k)."""
    from colorglove_ros.core.hand.gestures import GESTURE_NAMES
    from colorglove_ros.core.hand.observation_features import num_observation_features
    from colorglove_ros.core.hand.pose_classifier import train_pose_classifier

    classes = (*GESTURE_NAMES, NO_GESTURE)
    rng = np.random.default_rng(0)
    x = rng.normal(0.0, 0.1, (len(classes) * 20, num_observation_features()))
    y = np.repeat(np.array(classes), 20)
    for k, c in enumerate(classes):
        x[y == c, k] += 3.0
    return train_pose_classifier(x, y, feature_set, kind='lda')


def test_the_image_classifier_is_multiplied_with_the_pose_classifier() -> None:
    """With an image classifier, a frame's gesture probabilities are the pose classifier's
    times the image one's raised to image_weight, renormalised: an open hand whose image says
    index pinch starts a pinch when the image weighs enough, the open hand at weight 0 and
    without an observation; the image needs a pose classifier and gesture classes (the
    geometric bounds off: they would refuse a pinch to a flat hand whatever the image says)."""
    from colorglove_ros.core.hand.gestures import GESTURE_NAMES
    from colorglove_ros.core.hand.observation_features import num_observation_features

    image = _gesture_image_classifier()
    says_pinch = np.zeros(num_observation_features())
    says_pinch[GESTURE_NAMES.index('pinch_index')] = 3.0
    q = _pose('flat')

    def starts(weight: float, observation: np.ndarray | None) -> list[str]:
        detector = GestureDetector(MODEL, GestureConfig(image_weight=weight,
                                                        shape=ShapeGate()), _shipped(), image)
        events = []
        for k in range(20):
            events += detector.update(q, k / 30.0, None, observation)
        return [e.name for e in events if e.state == 'start']

    assert starts(0.0, says_pinch) == ['open_hand']
    assert starts(20.0, None) == ['open_hand']
    assert starts(20.0, says_pinch) == ['pinch_index']
    detector = GestureDetector(MODEL, GestureConfig(image_weight=1.0, shape=ShapeGate()),
                               _shipped(), image)
    pose_part = _shipped().pose_log_proba(MODEL, q)
    image_part = image.log_proba(says_pinch)[[image.classes.index(c)
                                              for c in _shipped().classes]]
    product = np.exp(pose_part + image_part)
    scores = detector.frame_scores(q, says_pinch)
    for c, p in zip(_shipped().classes, product / product.sum(), strict=True):
        if c != NO_GESTURE:
            assert scores[c] == pytest.approx(p)
    with pytest.raises(GestureError, match='pose classifier'):
        GestureDetector(MODEL, image_classifier=image)
    with pytest.raises(GestureError, match='tiny_observation'):
        GestureDetector(MODEL, classifier=_shipped(), image_classifier=_shipped())
    with pytest.raises(GestureError):
        GestureConfig(image_weight=-1.0)


def test_an_upright_image_classifier_is_read_with_features_turned_by_the_seen_pose(
        tmp_path) -> None:
    """An image classifier of the upright features is saved, read back and taken by the
    detector; the evaluation gives it each frame's features turned by that frame's seen pose
    (a lost frame's by none), the plain classifier the plain features."""
    from colorglove_ros.core.evaluation.scripted_hands import observation_seen
    from colorglove_ros.core.hand.observation_features import (
        OBSERVATION_UPRIGHT_FEATURES,
        empty_observation_record,
        feature_set_features,
        record_features,
    )
    from colorglove_ros.core.hand.pose_classifier import save_pose_classifier

    path = save_pose_classifier(tmp_path / 'upright.npz',
                                _gesture_image_classifier(OBSERVATION_UPRIGHT_FEATURES))
    upright = load_pose_classifier(path)
    assert upright.feature_set == OBSERVATION_UPRIGHT_FEATURES
    GestureDetector(MODEL, classifier=_shipped(), image_classifier=upright)
    record = empty_observation_record(3)
    record['tiny_labels'][:, 12:28, 18:22] = 3
    record['tiny_labels'][:, 12:16, 18:22] = 5
    seen = np.zeros((3, 26))
    seen[0, 3:6] = [0.0, 0.0, 0.7]
    seen[1, 3:6] = [0.0, 0.0, -0.7]
    seen[2] = np.nan                            # lost

    class Source:
        def observation(self, *args: object) -> dict[str, np.ndarray]:
            return record

    turned = observation_seen(Source(), 'gestures', 0, None, MODEL,
                              feature_set=OBSERVATION_UPRIGHT_FEATURES, seen=seen)
    expected = seen[:, 3:6].copy()
    expected[2] = 0.0
    np.testing.assert_allclose(turned, feature_set_features(record, OBSERVATION_UPRIGHT_FEATURES,
                                                            expected))
    assert np.abs(turned[0] - turned[1]).max() > 0.1     # the same image, other angles
    np.testing.assert_array_equal(observation_seen(Source(), 'gestures', 0, None, MODEL),
                                  record_features(record))


def test_the_shipped_upright_gesture_image_classifier_reads_upright_features() -> None:
    """config/gesture_upright_image_classifier.npz classifies the upright image features into
    the gestures and none, and the detector takes it beside the shipped pose classifier."""
    from colorglove_ros.core.hand.gestures import GESTURE_NAMES, GESTURE_UPRIGHT_IMAGE_CLASSIFIER
    from colorglove_ros.core.hand.observation_features import (
        OBSERVATION_UPRIGHT_FEATURES,
        num_observation_features,
    )

    clf = load_pose_classifier(share_dir() / GESTURE_UPRIGHT_IMAGE_CLASSIFIER,
                               OBSERVATION_UPRIGHT_FEATURES)
    assert set(clf.classes) == {*GESTURE_NAMES, NO_GESTURE}
    assert 'tiny_observation_upright' in clf.source
    assert clf.mean.shape == (num_observation_features(),)
    GestureDetector(MODEL, classifier=_shipped(), image_classifier=clf)


def test_the_shipped_gesture_image_classifier_reads_the_gesture_classes() -> None:
    """config/gesture_image_classifier.npz classifies tiny_observation features into the
    gestures and none, trained on rendered gesture holds, and the detector takes it beside the
    shipped pose classifier."""
    from colorglove_ros.core.hand.gestures import GESTURE_IMAGE_CLASSIFIER, GESTURE_NAMES
    from colorglove_ros.core.hand.observation_features import (
        OBSERVATION_FEATURES,
        num_observation_features,
    )

    clf = load_pose_classifier(share_dir() / GESTURE_IMAGE_CLASSIFIER, OBSERVATION_FEATURES)
    assert set(clf.classes) == {*GESTURE_NAMES, NO_GESTURE}
    assert clf.mean.shape == (num_observation_features(),)
    assert '--what gesture_images' in clf.source
    GestureDetector(MODEL, classifier=_shipped(), image_classifier=clf)
