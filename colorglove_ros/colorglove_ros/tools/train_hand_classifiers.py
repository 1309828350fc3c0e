"""Train the gesture and finger-spelling classifiers on synthetic data.

Training sequences are the evaluations' own scripts (``eval_gestures.gesture_script``,
``eval_spelling.spelling_script``) on TRAINING seeds (default 1000 onwards: neither the
hold-time tuning seeds 0-4 nor the report seeds 100-119), each seen ``--noise-draws`` times
through the tracking-noise model fitted to the tracker (``config/tracking_noise.yaml``, each
draw seeded). With ``--tracker-seeds``, the tracker's own output on the rendered scripted
sequences of those training seeds (``core/evaluation/scripted_tracking.py``, the sequences the
evaluations' ``--tracker`` runs, of ``--tracker-words`` words or ``--tracker-episodes``
episodes; cached in ``data/scripted_tracking/``, tracked there when missing, which is slow)
is added, each tracked frame ``--tracker-repeats`` times: the noise model has one bias per
joint, the tracker a bias that depends on the hand shape, which the classifier then learns.
Every frame of a hold is a sample labelled with what is held (a gesture, ``none`` for the
neutral shapes, or a letter); lost frames are left out. ``--model`` picks the classifier
(``core/hand/pose_classifier.py``: ``mlp``, ``lda`` or ``qda`` with
``--covariance-blend``). The classifiers are written as
versioned ``.npz`` files, by default ``config/gesture_classifier.npz`` and
``config/letter_classifier.npz``, which the nodes and the evaluations read.

``--what letter_images`` trains the letter classifier of the image evidence instead
(``core/hand/observation_features.py``): every ``--image-every``-th frame of each hold of the
spelling scripts of ``--image-seeds`` (training seeds), rendered as the evaluations'
``--tracker`` renders them and seen through the segmentation alone (no lookup, no IK; cached in
``data/scripted_tracking/``), its tiny label image and blobs; written to ``--image-output``
(off by default: the evaluations and the spelling node use it when given one).
``--what gesture_images`` does the same for the gestures: the holds of the gesture scripts of
``--image-seeds`` (``--image-episodes`` episodes each; the neutral shapes labelled ``none``),
written to ``--gesture-image-output``; ``--image-features tiny_observation_upright`` turns
each frame's features upright by its true pose's in-plane angle
(``observation_features.image_angle``; the evaluations turn the tracked frames by the fitted
pose's).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from colorglove_ros.core.evaluation.scripted_hands import (
    PoseSource,
    load_tracking_noise,
    script_poses,
)
from colorglove_ros.core.evaluation.sequences import LABEL_SOURCES, find_database
from colorglove_ros.core.hand.gestures import (
    DEFAULT_GESTURE_CLASSIFIER,
    GESTURE_FEATURES,
    GESTURE_IMAGE_CLASSIFIER,
    NO_GESTURE,
)
from colorglove_ros.core.hand.model import HandModel
from colorglove_ros.core.hand.observation_features import (
    IMAGE_FEATURE_SETS,
    OBSERVATION_FEATURES,
    feature_set_features,
)
from colorglove_ros.core.hand.pose_classifier import (
    MODEL_KINDS,
    ClassifierError,
    pose_features,
    save_pose_classifier,
    train_pose_classifier,
)
from colorglove_ros.core.hand.spelling import (
    LETTER_FEATURES,
    LETTER_IMAGE_CLASSIFIER,
    TRAINED_LETTER_CLASSIFIER,
)
from colorglove_ros.core.report import print_table
from colorglove_ros.paths import data_dir, share_dir
from colorglove_ros.tools import eval_gestures, eval_spelling
from colorglove_ros.tools._cli import run_tool, tool_parser

__all__ = ['main', 'training_samples', 'image_training_samples']


def image_training_samples(model: HandModel, scripts: Sequence[tuple[int, list]],
                           tracker: Any, every: int, name: str = 'spelling',
                           none_label: str = NO_GESTURE,
                           feature_set: str = OBSERVATION_FEATURES
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Observation features of ``feature_set`` (the upright ones turned by the true pose) and
    labels (what is held; ``none_label`` for a neutral shape) of every ``every``-th hold frame
    of the ``(seed, segments)`` scripts of sequences ``name``
    (``ScriptedTracker.hold_observations``)."""
    features, labels = [], []
    for seed, segments in scripts:
        truth = script_poses(segments)
        frames, record = tracker.hold_observations(name, seed, truth, every)
        features.append(feature_set_features(record, feature_set, truth.poses[frames, 3:6]))
        labels += [y or none_label for y in truth.label[frames]]
    return np.concatenate(features), np.asarray(labels).astype(str)


def training_samples(model: HandModel, scripts: list, noise, draws: int, feature_set: str,
                     none_label: str = NO_GESTURE, tracked: Sequence[tuple[int, list]] = (),
                     tracker: PoseSource | None = None, name: str = '', repeats: int = 1
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Features and labels of the hold frames of ``(seed, segments)`` scripts, each seen
    through ``draws`` seeded draws of ``noise``, and of the ``tracked`` scripts as ``tracker``
    sees them (sequences ``name`` / seed; found frames only), each such frame ``repeats``
    times."""
    features, labels = [], []
    for seed, segments in scripts:
        truth = script_poses(segments)
        hold = truth.holding
        for draw in range(draws):
            noisy = noise.apply(np.random.default_rng([seed, draw, 31]), truth.poses,
                                truth.fps, model)
            features.append(pose_features(model, noisy[hold], feature_set))
            labels += [x or none_label for x in truth.label[hold]]
    if tracked and tracker is None:
        raise ValueError('tracked scripts need a tracker')
    for seed, segments in tracked:
        truth = script_poses(segments)
        seen, found = tracker.observe(name, seed, truth, model)
        hold = truth.holding & found
        if hold.any():
            x = pose_features(model, seen[hold], feature_set)
            features += [x] * repeats
            labels += [y or none_label for y in truth.label[hold]] * repeats
    return np.concatenate(features), np.asarray(labels)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``colorglove_train_hand_classifiers``."""
    config = share_dir() / 'config'
    parser = tool_parser(__doc__, raw_description=True, json_help=None)
    parser.add_argument('--what', choices=('gestures', 'letters', 'both', 'letter_images',
                                           'gesture_images'),
                        default='both')
    parser.add_argument('--first-seed', type=int, default=1000)
    parser.add_argument('--gesture-sequences', type=int, default=12)
    parser.add_argument('--episodes', type=int, default=40)
    parser.add_argument('--spelling-sequences', type=int, default=20)
    parser.add_argument('--words', type=int, default=8)
    parser.add_argument('--noise-draws', type=int, default=2)
    parser.add_argument('--noise-config', type=Path, default=config / 'tracking_noise.yaml')
    parser.add_argument('--tracker-seeds', type=int, nargs='*', default=[],
                        help='training seeds whose tracked sequences are added (default none)')
    parser.add_argument('--tracker-words', type=int, default=4,
                        help='words per tracked spelling sequence')
    parser.add_argument('--tracker-episodes', type=int, default=30,
                        help='episodes per tracked gesture sequence')
    parser.add_argument('--tracker-repeats', type=int, default=3,
                        help='times each tracked frame counts')
    parser.add_argument('--labels', choices=LABEL_SOURCES, default='segmented',
                        help="the tracker's labels (as the evaluations' --labels)")
    parser.add_argument('--model', choices=MODEL_KINDS, default='mlp', help='classifier kind')
    parser.add_argument('--covariance-blend', type=float, default=0.5,
                        help="with --model qda: the shared covariance's share in each "
                        "class's (0-1; 1 is the lda)")
    parser.add_argument('--hidden', type=int, default=64, help='hidden units')
    parser.add_argument('--alpha', type=float, default=1e-3, help='L2 penalty')
    parser.add_argument('--seed', type=int, default=0, help='initialisation seed')
    parser.add_argument('--gesture-output', type=Path,
                        default=share_dir() / DEFAULT_GESTURE_CLASSIFIER)
    parser.add_argument('--letter-output', type=Path,
                        default=share_dir() / TRAINED_LETTER_CLASSIFIER)
    parser.add_argument('--image-seeds', type=int, nargs='*', default=[],
                        help='with --what letter_images / gesture_images: the training '
                        'seeds whose scripts are rendered')
    parser.add_argument('--image-words', type=int, default=4,
                        help='words per rendered spelling sequence')
    parser.add_argument('--image-episodes', type=int, default=30,
                        help='episodes per rendered gesture sequence')
    parser.add_argument('--gesture-image-output', type=Path,
                        default=share_dir() / GESTURE_IMAGE_CLASSIFIER,
                        help='with --what gesture_images: the file written')
    parser.add_argument('--image-every', type=int, default=5,
                        help='every how many-th frame of a hold is rendered')
    parser.add_argument('--image-features', choices=IMAGE_FEATURE_SETS,
                        default=OBSERVATION_FEATURES,
                        help='with --what gesture_images: the image feature set (the letters '
                        'read the plain one)')
    parser.add_argument('--image-output', type=Path,
                        default=share_dir() / LETTER_IMAGE_CLASSIFIER,
                        help='with --what letter_images: the file written')
    args = parser.parse_args(argv)

    def body() -> int:
        model = HandModel()
        noise = load_tracking_noise(args.noise_config)
        seeds = lambda n: range(args.first_seed, args.first_seed + n)  # noqa: E731
        if any(s < args.first_seed for s in args.tracker_seeds):
            raise ClassifierError(f'tracker seeds must be training seeds (>= '
                                  f'{args.first_seed}), got {args.tracker_seeds}')
        jobs = []
        if args.what in ('gestures', 'both'):
            jobs.append(('gestures', GESTURE_FEATURES, args.gesture_output,
                         [(s, eval_gestures.gesture_script(model, s, args.episodes))
                          for s in seeds(args.gesture_sequences)],
                         [(s, eval_gestures.gesture_script(model, s, args.tracker_episodes))
                          for s in args.tracker_seeds],
                         f'--gesture-sequences {args.gesture_sequences} --episodes '
                         f'{args.episodes} --tracker-episodes {args.tracker_episodes}'))
        if args.what in ('letters', 'both'):
            jobs.append(('letters', LETTER_FEATURES, args.letter_output,
                         [(s, eval_spelling.spelling_script(model, s, args.words)[0])
                          for s in seeds(args.spelling_sequences)],
                         [(s, eval_spelling.spelling_script(model, s, args.tracker_words)[0])
                          for s in args.tracker_seeds],
                         f'--spelling-sequences {args.spelling_sequences} --words {args.words} '
                         f'--tracker-words {args.tracker_words}'))
        if args.what in ('letter_images', 'gesture_images'):
            return _train_images(args, model, config)
        tracker = None
        if args.tracker_seeds:
            from colorglove_ros.core.evaluation.scripted_tracking import ScriptedTracker

            tracker = ScriptedTracker(find_database(data_dir()), config / 'ik.yaml',
                                      config / 'calibration.yaml',
                                      data_dir() / 'scripted_tracking', args.labels)
        rows = []
        try:
            for what, feature_set, output, scripts, tracked, sizes in jobs:
                x, y = training_samples(model, scripts, noise, args.noise_draws, feature_set,
                                        tracked=tracked, tracker=tracker,
                                        name='gestures' if what == 'gestures' else 'spelling',
                                        repeats=args.tracker_repeats)
                tracked_seeds = ' '.join(str(s) for s in args.tracker_seeds)
                source = (f'colorglove_train_hand_classifiers --what {what} --first-seed '
                          f'{args.first_seed} {sizes} --noise-draws {args.noise_draws} '
                          f'--tracker-seeds {tracked_seeds} --tracker-repeats '
                          f'{args.tracker_repeats} --labels {args.labels} --model {args.model} '
                          f'--hidden {args.hidden} --alpha {args.alpha} --seed {args.seed} '
                          f'--covariance-blend {args.covariance_blend}; '
                          f'noise {args.noise_config.name}')
                clf = train_pose_classifier(x, y, feature_set, hidden=args.hidden,
                                            seed=args.seed, alpha=args.alpha, source=source,
                                            kind=args.model,
                                            covariance_blend=args.covariance_blend)
                save_pose_classifier(output, clf)
                accuracy = float(np.mean(np.asarray(clf.classes)[
                    np.argmax(clf.log_proba(x), axis=1)] == y))
                rows.append({'classifier': what, 'samples': len(y),
                             'classes': len(clf.classes), 'training frame accuracy': accuracy,
                             'file': str(output)})
                print(f'[train_hand_classifiers] {what}: {len(y)} samples', flush=True)
        finally:
            if tracker is not None:
                tracker.close()
        print_table(rows, 'Trained classifiers')
        return 0

    return run_tool('colorglove_train_hand_classifiers', body)


def _train_images(args: Any, model: HandModel, config: Path) -> int:
    """``--what letter_images`` / ``gesture_images``: the image evidence's letter or gesture
    classifier (module docstring)."""
    from colorglove_ros.core.evaluation.scripted_tracking import ScriptedTracker

    if not args.image_seeds or any(s < args.first_seed for s in args.image_seeds):
        raise ClassifierError(f'--image-seeds must be training seeds (>= {args.first_seed}), '
                              f'got {args.image_seeds}')
    tracker = ScriptedTracker(find_database(data_dir()), config / 'ik.yaml',
                              config / 'calibration.yaml', data_dir() / 'scripted_tracking',
                              args.labels)
    letters = args.what == 'letter_images'
    features = args.image_features
    if letters and features != OBSERVATION_FEATURES:
        raise ClassifierError(f'the letter image classifier reads {OBSERVATION_FEATURES!r} '
                              f'features, not {features!r}')
    if letters:
        name, size, output = 'spelling', f'--image-words {args.image_words}', args.image_output
        scripts = [(s, eval_spelling.spelling_script(model, s, args.image_words)[0])
                   for s in args.image_seeds]
    else:
        name, size = 'gestures', f'--image-episodes {args.image_episodes}'
        output = args.gesture_image_output
        scripts = [(s, eval_gestures.gesture_script(model, s, args.image_episodes))
                   for s in args.image_seeds]
    try:
        x, y = image_training_samples(model, scripts, tracker, args.image_every, name,
                                      feature_set=features)
    finally:
        tracker.close()
    seeds = ' '.join(str(s) for s in args.image_seeds)
    source = (f'colorglove_train_hand_classifiers --what {args.what} --image-seeds {seeds} '
              f'{size} --image-every {args.image_every} --image-features {features} --labels '
              f'{args.labels} --model {args.model} --covariance-blend {args.covariance_blend}')
    clf = train_pose_classifier(x, y, features, hidden=args.hidden, seed=args.seed,
                                alpha=args.alpha, source=source, kind=args.model,
                                covariance_blend=args.covariance_blend)
    save_pose_classifier(output, clf)
    accuracy = float(np.mean(np.asarray(clf.classes)[np.argmax(clf.log_proba(x), axis=1)] == y))
    print_table([{'classifier': args.what.replace('_', ' '), 'samples': len(y),
                  'classes': len(clf.classes), 'training frame accuracy': accuracy,
                  'file': str(output)}],
                'Trained classifiers')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
