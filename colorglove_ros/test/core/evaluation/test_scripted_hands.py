"""The tracking-noise model: per-joint weights and bias, fitted back from its own output, and
its versioned file."""
from __future__ import annotations

import numpy as np
import pytest

from colorglove_ros.core.evaluation.scripted_hands import (
    ScriptError,
    TrackingNoise,
    fit_tracking_noise,
    load_tracking_noise,
    save_tracking_noise,
)
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.poses import GESTURE_SHAPES

MODEL = HandModel()


def _truth(n: int) -> np.ndarray:
    q = MODEL.rest_pose()
    q[2] = 0.5
    q[6:] = GESTURE_SHAPES['relaxed']
    return np.tile(q, (n, 1))


def test_fit_recovers_the_model() -> None:
    weights = np.linspace(0.5, 1.5, 20)
    bias = np.zeros(20)
    bias[5] = 6.0
    noise = TrackingNoise(joint_mae_deg=6.0, rotation_mae_deg=3.0, slow_share=0.8,
                          correlation_s=0.5, joint_weights=tuple(weights / weights.mean()),
                          joint_bias_deg=tuple(bias))
    truths = [_truth(3000) for _ in range(4)]
    seen = [noise.apply(np.random.default_rng(k), t, 30.0, MODEL) for k, t in enumerate(truths)]
    found = [np.ones(len(t), bool) for t in truths]
    fit = fit_tracking_noise(truths, seen, found, 30.0)
    assert fit.joint_mae_deg == pytest.approx(6.0, rel=0.02)
    assert fit.rotation_mae_deg == pytest.approx(3.0, rel=0.1)
    assert fit.slow_share == pytest.approx(0.8, abs=0.1)
    assert fit.correlation_s == pytest.approx(0.5, rel=0.3)
    assert fit.joint_bias_deg[5] == pytest.approx(6.0, abs=1.5)
    assert np.corrcoef(fit.joint_weights, weights)[0, 1] > 0.9


def test_white_noise_fits_no_slow_part_and_lost_frames_are_skipped() -> None:
    truth = _truth(2000)
    seen = TrackingNoise(5.0, 2.0, slow_share=0.0).apply(np.random.default_rng(0), truth,
                                                          30.0, MODEL)
    found = np.ones(len(truth), bool)
    found[::7] = False
    seen[~found] = np.nan
    fit = fit_tracking_noise([truth], [seen], [found], 30.0)
    assert fit.slow_share < 0.1
    assert np.isfinite(fit.joint_mae_deg)


def test_file_round_trip_and_refusals(tmp_path) -> None:
    noise = TrackingNoise(6.5, 3.0, 0.9, 0.6, tuple(np.ones(20)), tuple(np.arange(20.0)))
    path = save_tracking_noise(tmp_path / 'n.yaml', noise, 'a test')
    assert load_tracking_noise(path) == noise
    text = path.read_text()
    (tmp_path / 'v2.yaml').write_text(text.replace('version: 1', 'version: 2'))
    with pytest.raises(ScriptError, match='version'):
        load_tracking_noise(tmp_path / 'v2.yaml')
    (tmp_path / 'short.yaml').write_text(text.replace('slow_share', 'slow'))
    with pytest.raises(ScriptError, match='lacks'):
        load_tracking_noise(tmp_path / 'short.yaml')
    with pytest.raises(ScriptError):
        TrackingNoise(joint_weights=(1.0, 2.0))
    scaled = noise.with_joint_mae(13.0)
    assert scaled.joint_bias_deg[4] == pytest.approx(8.0)


def test_evidence_seen_is_each_frames_own() -> None:
    """A consumer node pairs each pose with its frame's status line (by stamp): frame i sees
    frame i's evidence, none for a lost frame, none at all from the noise model."""
    from types import SimpleNamespace

    from colorglove_ros.core.evaluation.scripted_hands import evidence_seen
    from colorglove_ros.core.hand.frame_evidence import FrameEvidence

    truth = SimpleNamespace(poses=np.zeros((4, 26)))
    record = {'constraints': np.array([12.0, np.nan, 9.0, 15.0]),
              'reprojection_px': np.array([2.0, np.nan, 4.0, 1.0])}
    source = SimpleNamespace(evidence=lambda name, seed, t, model: record)
    seen = evidence_seen(source, 'gestures', 1, truth, None)
    assert seen == [FrameEvidence(12.0, 2.0), None, FrameEvidence(9.0, 4.0),
                    FrameEvidence(15.0, 1.0)]
    assert evidence_seen(SimpleNamespace(), 'gestures', 1, truth, None) == [None] * 4


def test_observation_seen_reads_the_sources_record_and_refuses_the_noise_model() -> None:
    """The image classifiers' input in the evaluations: the recorded observation of each frame
    as features (``record_features``); a source that records none (the noise model) is a clear
    error, not an image-free run."""
    from types import SimpleNamespace

    from colorglove_ros.core.evaluation.scripted_hands import (
        ScriptError,
        TrackingNoise,
        observation_seen,
    )
    from colorglove_ros.core.hand.observation_features import (
        empty_observation_record,
        num_observation_features,
        record_features,
    )

    record = empty_observation_record(3)
    record['tiny_labels'][1, 10:20, 10:20] = 4
    asked = []
    source = SimpleNamespace(observation=lambda name, seed, t, model: asked.append(
        (name, seed)) or record)
    seen = observation_seen(source, 'spelling', 7, None, None)
    assert asked == [('spelling', 7)]
    assert seen.shape == (3, num_observation_features())
    assert np.array_equal(seen, record_features(record))
    with pytest.raises(ScriptError, match="needs the frames' observation"):
        observation_seen(TrackingNoise(), 'gestures', 1, None, None)
