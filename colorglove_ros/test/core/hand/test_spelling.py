"""Finger-spelling: templates classify as themselves, hold-to-commit timing and double letters,
and the evaluation's scoring."""
from __future__ import annotations

import numpy as np
import pytest
from pose_samples import MODEL, allowed_fingers

from colorglove_ros.core.evaluation.scripted_hands import (
    ScriptError,
    Segment,
    TrackingNoise,
    classify_holds,
    script_poses,
)
from colorglove_ros.core.hand.pose_classifier import load_pose_classifier
from colorglove_ros.core.hand.poses import LETTER_SHAPES
from colorglove_ros.core.hand.spelling import (
    LETTER_FEATURES,
    LETTERS,
    TRAINED_LETTER_CLASSIFIER,
    LetterClassifier,
    Speller,
    SpellingConfig,
    SpellingError,
    letter_rotation,
    pointing_direction,
)
from colorglove_ros.paths import share_dir
from colorglove_ros.tools import eval_spelling


def _segment(letter: str, position=(0.0, 0.05, 0.5), hold_s: float = 0.8) -> Segment:
    return Segment(letter, allowed_fingers(LETTER_SHAPES[letter]), letter_rotation(letter),
                   np.asarray(position, dtype=float), hold_s=hold_s, move_s=0.3)


def _spell(segments: list[Segment], speller: Speller | None = None) -> list[tuple[float, str]]:
    truth = script_poses(segments, 30.0)
    speller = Speller(model=MODEL) if speller is None else speller
    out = []
    for q, t in zip(truth.poses, truth.times, strict=True):
        letter = speller.update(q, float(t))
        if letter:
            out.append((float(t), letter))
    return out


def test_every_template_is_its_own_letter() -> None:
    classifier = LetterClassifier(model=MODEL)
    q = MODEL.rest_pose()
    for letter in LETTERS:
        q[3:6] = letter_rotation(letter)
        q[6:] = allowed_fingers(LETTER_SHAPES[letter])
        assert LETTERS[int(np.argmax(classifier.log_likelihoods(q)))] == letter


def test_orientation_separates_h_from_u() -> None:
    q = MODEL.rest_pose()
    q[6:] = LETTER_SHAPES['H']
    np.testing.assert_allclose(pointing_direction(q), [0.0, -1.0, 0.0], atol=1e-12)
    classifier = LetterClassifier(model=MODEL)
    assert LETTERS[int(np.argmax(classifier.log_likelihoods(q)))] == 'U'
    q[3:6] = letter_rotation('H')
    assert LETTERS[int(np.argmax(classifier.log_likelihoods(q)))] == 'H'


def _still_or_moving(letter: str, seconds: float, start: float, speed: float = 0.0,
                     x0: float = 0.0) -> list[tuple[np.ndarray, float]]:
    """(pose, stamp) frames at 30 Hz of ``letter`` held for ``seconds`` from ``start``, the wrist
    moving sideways at ``speed`` (m/s) from ``x0``."""
    q = MODEL.rest_pose()
    q[3:6] = letter_rotation(letter)
    q[6:] = allowed_fingers(LETTER_SHAPES[letter])
    frames = []
    for k in range(int(round(seconds * 30.0))):
        p = q.copy()
        p[0:3] = [x0 + speed * k / 30.0, 0.05, 0.5]
        frames.append((p, start + k / 30.0))
    return frames


def test_hold_to_commit_and_double_letters() -> None:
    word = [_segment('H'), _segment('E'), _segment('L'),
            _segment('L', position=(0.05, 0.05, 0.5)), _segment('O')]
    commits = _spell(word)
    assert ''.join(letter for _, letter in commits) == 'HELLO'
    # each letter commits at least commit_after_s after its move began
    starts = np.cumsum([0.0] + [s.move_s + s.hold_s for s in word[:-1]])
    for (stamp, _), start in zip(commits, starts, strict=True):
        assert stamp >= start + SpellingConfig().commit_after_s
    # the same letter held in one place is committed once
    assert ''.join(x for _, x in _spell([_segment('L', hold_s=3.0)])) == 'L'


def test_a_moving_hand_commits_nothing_and_a_hold_commits_its_own_letter() -> None:
    speller = Speller(model=MODEL)
    # a T passing by while the hand moves, then an S held still: only the S
    frames = _still_or_moving('T', 0.6, 0.0, speed=0.3) + \
        _still_or_moving('S', 0.8, 0.6, x0=0.18)
    got = [speller.update(q, t) for q, t in frames]
    assert [x for x in got if x] == ['S']
    # still for less than commit_after_s, then lost: nothing
    speller.reset()
    short = _still_or_moving('A', SpellingConfig().commit_after_s - 0.05, 10.0)
    assert not any(speller.update(q, t) for q, t in short)
    assert speller.update(None, 10.5) is None


def test_the_hold_sum_decides_not_a_few_frames_of_another_letter() -> None:
    # templates: two frames of N, then M, in one place: the sum over the hold says M
    speller = Speller(model=MODEL)
    frames = _still_or_moving('N', 2 / 30.0, 0.0) + _still_or_moving('M', 0.5, 2 / 30.0)
    assert [x for x in (speller.update(q, t) for q, t in frames) if x] == ['M']


def test_lost_hand_resets() -> None:
    speller = Speller(model=MODEL)
    _spell([_segment('A')], speller)
    assert speller.update(None, 5.0) is None
    assert ''.join(x for _, x in _spell([_segment('A')], speller)) == 'A'
    with pytest.raises(SpellingError):
        speller.update(np.zeros(20), 6.0)
    with pytest.raises(SpellingError):
        SpellingConfig(commit_after_s=0.0)


def test_edit_distance() -> None:
    assert eval_spelling.edit_distance('MENTION', 'MENTION') == 0
    assert eval_spelling.edit_distance('MENTION', 'MENSION') == 1
    assert eval_spelling.edit_distance('NEST', 'NET') == 1
    assert eval_spelling.edit_distance('', 'ABC') == 3


def test_shipped_classifier_spells_clean_poses_and_heavy_noise_breaks_it() -> None:
    classifier = load_pose_classifier(share_dir() / TRAINED_LETTER_CLASSIFIER, LETTER_FEATURES)
    clean = eval_spelling.evaluate([11], words_per_sequence=4, source=TrackingNoise(0.0, 0.0),
                                   classifier=classifier)
    assert clean['letters'] >= 10
    assert clean['letter_accuracy'] >= 0.85 and clean['insertions'] <= 3
    noisy = eval_spelling.evaluate([11], words_per_sequence=4, source=TrackingNoise(25.0, 10.0),
                                   classifier=classifier)
    assert noisy['letter_accuracy'] < clean['letter_accuracy'] - 0.1
    rows = {row['scripted']: row for row in noisy['thumb_confusion']}
    assert set(rows) == {'E', 'M', 'N', 'S', 'T'}


def test_batch_log_likelihoods_match_one_pose_at_a_time() -> None:
    classifier = load_pose_classifier(share_dir() / TRAINED_LETTER_CLASSIFIER, LETTER_FEATURES)
    poses = []
    for letter in ('A', 'M', 'H'):
        q = MODEL.rest_pose()
        q[3:6] = letter_rotation(letter)
        q[6:] = allowed_fingers(LETTER_SHAPES[letter])
        poses.append(q)
    for letters in (LetterClassifier(model=MODEL),
                    LetterClassifier(model=MODEL, classifier=classifier)):
        batch = letters.log_likelihoods_batch(np.stack(poses))
        assert batch.shape == (3, 26)
        for q, row in zip(poses, batch, strict=True):
            np.testing.assert_allclose(row, letters.log_likelihoods(q), atol=1e-9)
    with pytest.raises(SpellingError):
        LetterClassifier(model=MODEL).log_likelihoods_batch(np.full((1, 26), np.nan))


def test_holds_are_classified_whole_and_lost_holds_give_nothing() -> None:
    truth = script_poses([_segment('M'), _segment('N'), _segment('S')], 30.0)
    log_likelihoods = np.full((len(truth.poses), 26), -10.0)
    hold = [np.flatnonzero((truth.segment == k) & truth.holding) for k in range(3)]
    # the M hold: N wins its first frame, M all the others: the sum says M
    log_likelihoods[hold[0], LETTERS.index('M')] = -1.0
    log_likelihoods[hold[0][0], LETTERS.index('N')] = 0.0
    log_likelihoods[hold[1], LETTERS.index('S')] = -1.0      # N held, S classified
    log_likelihoods[hold[2]] = np.nan                         # S lost
    pairs = classify_holds(truth, log_likelihoods, LETTERS)
    assert pairs == [('M', 'M'), ('N', 'S'), ('S', '-')]
    with pytest.raises(ScriptError):
        classify_holds(truth, log_likelihoods[:, :25], LETTERS)
    rows = {r['scripted']: r for r in eval_spelling.thumb_confusion(pairs)}
    assert rows['M']['M'] == 1 and rows['N']['S'] == 1 and rows['S']['-'] == 1
    assert rows['E'] == {'scripted': 'E', 'E': 0, 'M': 0, 'N': 0, 'S': 0, 'T': 0, 'other': 0,
                         '-': 0}
