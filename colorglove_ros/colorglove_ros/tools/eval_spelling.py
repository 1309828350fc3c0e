"""Evaluate finger-spelling (``core/hand/spelling.py``) on synthetic spelled words.

Each sequence spells words drawn from a fixed list that covers all 26 letters and stresses the
thumb letters E, M, N, S, T. Every letter is scripted (``core/evaluation/scripted_hands.py``)
as a minimum-jerk move (0.25-0.45 s) into its template (the pose collection's letter shape and
the letter's canonical orientation) plus the signer's variation (4 deg Gaussian per finger DOF,
8 deg per orientation axis), held 0.6-1.0 s; a double letter slides the hand 5 cm sideways.
The speller sees the poses through ``TrackingNoise``, a MODEL of the tracker's errors (default
mean absolute finger-joint error 7 deg after clipping, most of it slowly varying, plus 5 deg
per wrist orientation axis), not the tracker run on rendered frames. J and Z are static
handshapes here, as in the speller. With ``--tracker`` the speller also reads each frame's
image evidence (the observation the tracker got, recorded in the tracking cache) through the
image classifier (``--image-classifier``, default ``config/letter_image_classifier.npz``; ''
for the pose alone); the noise model has no image, so it is scored on the pose alone.

Scores: a committed letter belongs to the scripted letter whose window (the move into it and
its hold, plus 0.3 s) holds its commit time; a letter is right when the first letter committed
in its window is that letter. Letter accuracy = right / scripted letters; insertions = extra
commits. Text accuracy = 1 - edit distance / length over the whole committed text.

Hold accuracy separates the classifier from the commit timing: each scripted hold is classified
once, by the sum over its tracked frames of the per-frame letter log-probabilities (the letter
classifier alone, knowing when the hold starts and ends, which the speller does not); its
confusion of E, M, N, S, T shows which letters the tracked pose cannot tell apart.

The hold settings (``SpellingConfig``: still speed, window, commit time) were tuned on seeds
1100-1109 (noise model) and the tracker's output of seeds 1008, 1014, 1015, and checked on
seeds 2000-2009 and the tracker's output of 2000-2003; the default report seeds 100-119 were
not used for tuning (an earlier version's hold settings were tuned on seeds 0-4).
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from colorglove_ros.core.evaluation.scripted_hands import (
    PoseSource,
    ScriptedSequence,
    Segment,
    TrackingNoise,
    classify_holds,
    observation_seen,
    realised_joint_mae_deg,
    script_poses,
)
from colorglove_ros.core.evaluation.targets import target_row
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.pose_classifier import PoseClassifier
from colorglove_ros.core.hand.poses import LETTER_SHAPES, finger_limits
from colorglove_ros.core.hand.spelling import (
    DEFAULT_LETTER_CLASSIFIER,
    DEFAULT_LETTER_IMAGE_CLASSIFIER,
    LETTER_FEATURES,
    LETTERS,
    THUMB_LETTERS,
    Speller,
    SpellingConfig,
    SpellingError,
    letter_rotation,
)
from colorglove_ros.core.report import print_table
from colorglove_ros.tools._cli import ScriptedSettings, run_scripted_evaluation

__all__ = ['SETTINGS', 'WORDS', 'spelling_script', 'score_letters',
           'thumb_confusion', 'edit_distance', 'evaluate',
           'main']

TARGET = 0.90
SETTINGS = ScriptedSettings(tuning_seeds=tuple(range(1100, 1110)),
                            default_seeds=tuple(range(100, 120)),
                            unit='words', default_count=8,
                            classifier=DEFAULT_LETTER_CLASSIFIER, feature_set=LETTER_FEATURES,
                            image_classifier=DEFAULT_LETTER_IMAGE_CLASSIFIER)
WORDS: tuple[str, ...] = (
    'THE', 'QUICK', 'BROWN', 'FOX', 'JUMPS', 'OVER', 'LAZY', 'DOG', 'MENTION', 'SENSE', 'STEM',
    'MEET', 'TEST', 'NEST', 'MUST', 'MEAN', 'TENSE', 'NAMES', 'HELLO', 'ROBOT', 'GLOVE', 'HAND',
    'WAVE', 'PIZZA', 'KEY', 'EXIT', 'QUIZ', 'VIEW', 'SIGN', 'SPELL', 'WATCH', 'MONTH', 'SMART',
    'ENTER', 'STONE')
JOINT_VARIATION_DEG = 4.0
ORIENTATION_VARIATION_DEG = 8.0
DOUBLE_LETTER_SLIDE_M = 0.05
WINDOW_GRACE_S = 0.3

assert set(''.join(WORDS)) == set(LETTERS)


def spelling_script(model: HandModel, seed: int, num_words: int
                    ) -> tuple[list[Segment], str]:
    """A seeded script spelling ``num_words`` words; returns it and the spelled text."""
    rng = np.random.default_rng(seed)
    lo, hi = finger_limits(model)
    words = [WORDS[i] for i in rng.integers(len(WORDS), size=num_words)]
    text = ''.join(words)
    segments = []
    position = np.array([0.0, 0.05, 0.5])
    previous = None
    for letter in text:
        if letter == previous:
            position = position + np.array([DOUBLE_LETTER_SLIDE_M, 0.0, 0.0])
        else:
            position = np.array([rng.uniform(-0.05, 0.05), rng.uniform(0.0, 0.1),
                                 rng.uniform(0.45, 0.6)])
        fingers = LETTER_SHAPES[letter] + rng.normal(0.0, np.deg2rad(JOINT_VARIATION_DEG), 20)
        turn = Rotation.from_rotvec(rng.normal(0.0, np.deg2rad(ORIENTATION_VARIATION_DEG), 3))
        rotvec = (turn * Rotation.from_rotvec(letter_rotation(letter))).as_rotvec()
        segments.append(Segment(label=letter, fingers=np.clip(fingers, lo, hi), rotvec=rotvec,
                                position=position, hold_s=float(rng.uniform(0.6, 1.0)),
                                move_s=float(rng.uniform(0.25, 0.45))))
        previous = letter
    return segments, text


def edit_distance(a: str, b: str) -> int:
    """Levenshtein distance between two strings."""
    row = list(range(len(b) + 1))
    for i, ca in enumerate(a, start=1):
        prev, row[0] = row[0], i
        for j, cb in enumerate(b, start=1):
            prev, row[j] = row[j], min(row[j] + 1, row[j - 1] + 1, prev + (ca != cb))
    return row[-1]


def score_letters(truth: ScriptedSequence, commits: Sequence[tuple[float, str]]
                  ) -> tuple[list[tuple[str, str]], int]:
    """(scripted, first committed or '-') per scripted letter, and the insertions."""
    t = truth.times
    windows = []
    for k in np.unique(truth.segment):
        frames = np.flatnonzero(truth.segment == k)
        windows.append((truth.label[frames[0]], float(t[frames[0]]),
                        float(t[frames[-1]]) + WINDOW_GRACE_S))
    firsts: list[str | None] = [None] * len(windows)
    insertions = 0
    for stamp, letter in commits:
        # the latest window that has started by the commit and is not over
        owner = next((w for w in range(len(windows) - 1, -1, -1)
                      if windows[w][1] <= stamp <= windows[w][2]), None)
        if owner is None or firsts[owner] is not None:
            insertions += 1
        else:
            firsts[owner] = letter
    return [(w[0], f or '-') for w, f in zip(windows, firsts, strict=True)], insertions


def thumb_confusion(pairs: Sequence[tuple[str, str]]) -> list[dict]:
    """Per thumb letter: how often each thumb letter, another letter ('other') or nothing
    ('-') was given for it."""
    thumb = [p for p in pairs if p[0] in THUMB_LETTERS]
    rows = []
    for a in THUMB_LETTERS:
        given = [y for x, y in thumb if x == a]
        row = {'scripted': a, **{b: given.count(b) for b in THUMB_LETTERS}}
        row['other'] = sum(1 for y in given if y not in THUMB_LETTERS and y != '-')
        row['-'] = given.count('-')
        rows.append(row)
    return rows


def _accuracies(pairs: Sequence[tuple[str, str]]) -> tuple[float, float, float]:
    """Accuracy over all, the thumb letters and the other letters."""
    def share(subset: list[tuple[str, str]]) -> float:
        return sum(a == b for a, b in subset) / max(len(subset), 1)
    return (share(list(pairs)), share([p for p in pairs if p[0] in THUMB_LETTERS]),
            share([p for p in pairs if p[0] not in THUMB_LETTERS]))


def evaluate(seeds: Sequence[int], words_per_sequence: int = 8,
             source: PoseSource | None = None, classifier: PoseClassifier | None = None,
             config: SpellingConfig | None = None, fps: float = 30.0,
             image_classifier: PoseClassifier | None = None,
             image_weight: float | None = None) -> dict:
    """Letter accuracy, thumb-letter confusion and text accuracy over ``seeds``, as seen
    through ``source`` (default: the built-in ``TrackingNoise``; frames the tracker lost reach
    the speller as 'no hand'), classified by ``classifier`` (None: the templates) and, given,
    ``image_classifier`` on each frame's observation (a source that records it, the tracker;
    weighted by ``image_weight``, default the config's)."""
    model = HandModel()
    source = TrackingNoise() if source is None else source
    if image_weight is not None:
        config = replace(config or SpellingConfig(), image_weight=image_weight)
    pairs: list[tuple[str, str]] = []
    hold_pairs: list[tuple[str, str]] = []
    insertions = 0
    edits = 0
    length = 0
    maes = []
    for seed in seeds:
        segments, text = spelling_script(model, seed, words_per_sequence)
        truth = script_poses(segments, fps)
        seen, found = source.observe('spelling', seed, truth, model)
        maes.append(realised_joint_mae_deg(truth.poses, seen, found))
        speller = Speller(config, model, classifier, image_classifier)
        observed: Any = ([None] * len(seen) if image_classifier is None
                         else observation_seen(source, 'spelling', seed, truth, model,
                                              SpellingError))
        frame_log_likelihoods = np.full((len(seen), len(LETTERS)), np.nan)
        frame_log_likelihoods[found] = speller.classifier.log_likelihoods_batch(
            seen[found], None if image_classifier is None else observed[found])
        hold_pairs += classify_holds(truth, frame_log_likelihoods, LETTERS)
        commits = []
        for q, ok, stamp, obs in zip(seen, found, truth.times, observed, strict=True):
            letter = speller.update(q if ok else None, float(stamp), obs)
            if letter is not None:
                commits.append((float(stamp), letter))
        seq_pairs, seq_insertions = score_letters(truth, commits)
        pairs += seq_pairs
        insertions += seq_insertions
        edits += edit_distance(text, ''.join(letter for _, letter in commits))
        length += len(text)
    per_letter = []
    for letter in LETTERS:
        got = Counter(b for a, b in pairs if a == letter)
        n = sum(got.values())
        wrong = ' '.join(f'{k}:{v}' for k, v in got.most_common() if k != letter)
        per_letter.append({'letter': letter, 'n': n,
                           'accuracy': got[letter] / n if n else float('nan'),
                           'confused_with': wrong or '-'})
    accuracy, thumb_accuracy, other_accuracy = _accuracies(pairs)
    hold_accuracy, hold_thumb_accuracy, _ = _accuracies(hold_pairs)
    return {
        'letters': len(pairs), 'letter_accuracy': accuracy,
        'thumb_letters': sum(1 for p in pairs if p[0] in THUMB_LETTERS),
        'thumb_letter_accuracy': thumb_accuracy, 'other_letter_accuracy': other_accuracy,
        'insertions': insertions, 'text_accuracy': 1.0 - edits / max(length, 1),
        'hold_letter_accuracy': hold_accuracy, 'hold_thumb_letter_accuracy': hold_thumb_accuracy,
        'joint_mae_deg_realised': float(np.nanmean(maes)),
        'per_letter': per_letter, 'thumb_confusion': thumb_confusion(pairs),
        'hold_thumb_confusion': thumb_confusion(hold_pairs)}


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``colorglove_eval_spelling``."""
    run = run_scripted_evaluation(argv, __doc__, SETTINGS, evaluate)
    result = run.result
    rows = result['per_letter']
    print_table([r for r in rows if r['letter'] not in THUMB_LETTERS],
                run.title('Finger-spelling per letter (all but E M N S T)'))
    print_table([r for r in rows if r['letter'] in THUMB_LETTERS],
                'The thumb letters E, M, N, S, T')
    print_table(result['thumb_confusion'], 'E, M, N, S, T: what was committed (- = nothing)')
    print_table(result['hold_thumb_confusion'], 'E, M, N, S, T: each whole hold classified '
                '(the classifier alone, hold known)')
    summary = {k: result[k] for k in ('letters', 'letter_accuracy', 'thumb_letter_accuracy',
                                      'other_letter_accuracy', 'insertions', 'text_accuracy',
                                      'hold_letter_accuracy', 'hold_thumb_letter_accuracy')}
    print_table([summary], 'Overall')
    targets = [target_row('letter accuracy >= 90 %', result['letter_accuracy'], TARGET, '>='),
               {'target': 'E M N S T (reported separately)',
                'measured': result['thumb_letter_accuracy'], 'result': '-'}]
    print_table(targets, 'Targets')
    return run.finish(targets)

if __name__ == '__main__':
    raise SystemExit(main())
