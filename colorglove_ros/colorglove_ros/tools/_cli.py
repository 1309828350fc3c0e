"""What every command-line tool shares: its parser with ``--json``, and one error policy."""
from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.frame_evidence import EvidenceGate
from colorglove_ros.core.opencv_threads import OPENCV_THREADS
from colorglove_ros.core.report import write_json
from colorglove_ros.signal_exit import exit_on_signals

__all__ = ['tool_parser', 'sequence_tool_parser', 'ScriptedSettings', 'ScriptedEvaluation',
           'run_scripted_evaluation', 'add_pipeline_arguments', 'add_opencv_threads_argument',
           'tool_error', 'run_tool']


def tool_parser(description: str | None, *, raw_description: bool = False,
                json_help: str | None = 'also write the figures to this JSON file'
                ) -> argparse.ArgumentParser:
    """An argument parser with the ``--json PATH`` option every evaluation and benchmark has
    (``json_help=None``: a tool that writes no figures)."""
    formatter = (argparse.RawDescriptionHelpFormatter if raw_description
                 else argparse.HelpFormatter)
    parser = argparse.ArgumentParser(description=description, formatter_class=formatter)
    if json_help is not None:
        parser.add_argument('--json', type=Path, metavar='PATH', help=json_help)
    return parser


def sequence_tool_parser(description: str | None, sequences_help: str
                         ) -> argparse.ArgumentParser:
    """The parser of the tools that run the tracker over synthetic sequences (eval_ik,
    learn_ik_covariances): ``--json``, database, sequences (``sequences_help``), frames, label
    source, colour, IK and camera configuration, frame rate."""
    from colorglove_ros.core.evaluation.sequences import LABEL_SOURCES
    from colorglove_ros.paths import share_dir

    config = share_dir() / 'config'
    parser = tool_parser(description, raw_description=True)
    parser.add_argument('--database', help='pose database directory (default: the largest '
                        'under data/)')
    parser.add_argument('--sequences', type=int, default=4, help=sequences_help)
    parser.add_argument('--frames', type=int, default=150, help='frames per sequence')
    parser.add_argument('--labels', choices=LABEL_SOURCES, default='truth',
                        help="'truth': the renderer's labels (the IK and lookup without the "
                             "colour segmentation); 'segmented': the colour segmentation "
                             '(core.segmentation) of the rendered images')
    parser.add_argument('--color-config', help='colour calibration YAML for --labels '
                        'segmented (default config/color_calibration.yaml)')
    parser.add_argument('--ik-config', default=str(config / 'ik.yaml'))
    parser.add_argument('--calibration', default=str(config / 'calibration.yaml'),
                        help='camera rig the tracker runs with')
    parser.add_argument('--fps', type=float, default=30.0)
    return parser


@dataclass(frozen=True)
class ScriptedSettings:
    """An evaluation on scripted poses with a tracking-noise model (eval_gestures,
    eval_spelling): the sequence seeds its settings were tuned on, the held-out seeds it
    reports on by default, what its sequences are made of (``unit``, e.g. 'words', and
    how many per sequence by default), and its trained classifier."""

    tuning_seeds: tuple[int, ...]
    default_seeds: tuple[int, ...]
    unit: str
    default_count: int
    classifier: str               # default trained classifier (package-relative; '': none)
    feature_set: str              # its feature set (core.hand.pose_classifier)
    # when not None: evaluate(...) takes evidence=EvidenceGate, this one (the core's) with the
    # fields --evidence-* give replaced
    evidence_gate: EvidenceGate | None = None
    # evaluate(...) takes image_classifier= and image_weight= (--image-classifier, --image-weight)
    # when not None: the image classifier used with --tracker by default (package-relative;
    # '': none)
    image_classifier: str | None = None


@dataclass(frozen=True)
class ScriptedEvaluation:
    """A run of such an evaluation: its arguments, settings, what the consumers saw (the noise
    model or the tracker, ``source``; ``source_settings`` describes it), result and time."""

    args: argparse.Namespace
    settings: ScriptedSettings
    source: Any                   # TrackingNoise or ScriptedTracker
    source_settings: dict[str, Any]
    result: dict[str, Any]
    seconds: float

    @property
    def count(self) -> int:
        """Units per sequence."""
        return getattr(self.args, self.settings.unit)

    def title(self, what: str) -> str:
        """``what``, then the seeds, sequence size and the pose source (noise model with its
        set and realised joint error, or the tracker with its realised error)."""
        seeds = self.args.seeds
        realised = self.result['joint_mae_deg_realised']
        if self.args.tracker:
            seen = f'tracker output ({self.args.labels} labels), joint MAE {realised:.2f} deg'
        else:
            seen = (f'noise model {self.source_settings["noise_file"] or "(built-in)"}, '
                    f'joint MAE {self.source.joint_mae_deg:.2f} deg (realised {realised:.2f})')
        return (f'{what}, seeds {seeds[0]}..{seeds[-1]} ({len(seeds)} sequences x '
                f'{self.count} {self.settings.unit}), {seen}, classifier '
                f'{Path(self.source_settings["classifier"]).name}')

    def finish(self, targets: list[dict[str, Any]]) -> int:
        """Print the time; with ``--json`` write the settings (seeds, units per sequence, the
        pose source, tuning seeds), the result, ``targets`` and the time. Returns 0."""
        print(f'{self.seconds:.1f} s')
        if self.args.json:
            write_json(self.args.json, {
                'settings': {'seeds': self.args.seeds, self.settings.unit: self.count,
                             **self.source_settings,
                             'tuning_seeds': list(self.settings.tuning_seeds)},
                **self.result, 'targets': targets, 'seconds': self.seconds})
        return 0


def run_scripted_evaluation(argv: list[str] | None, description: str | None,
                            settings: ScriptedSettings,
                            evaluate: Callable[[list[int], int, Any, Any], dict[str, Any]]
                            ) -> ScriptedEvaluation:
    """Parse the arguments of an evaluation on scripted poses (held-out ``--seeds``, ``--UNIT``
    per sequence, and what the consumers see: the noise model of ``--noise-config`` at its own
    or ``--noise-mae-deg``'s level, or with ``--tracker`` the tracker's output on the rendered
    sequences) and run ``evaluate(seeds, count, source, classifier)``, timed (classifier: the
    trained one of ``--classifier``, or None with ``--rules``)."""
    from dataclasses import asdict

    from colorglove_ros.core.evaluation.scripted_hands import load_tracking_noise
    from colorglove_ros.core.evaluation.scripted_tracking import ScriptedTracker
    from colorglove_ros.core.evaluation.sequences import LABEL_SOURCES, find_database
    from colorglove_ros.core.pipeline import NODE_LIMITS, UNGATED
    from colorglove_ros.paths import data_dir, share_dir

    config = share_dir() / 'config'
    tuning, unit = settings.tuning_seeds, settings.unit
    parser = tool_parser(description, raw_description=True)
    parser.add_argument('--seeds', type=int, nargs='+', default=list(settings.default_seeds),
                        help=f'sequence seeds (tuning used {tuning[0]}-{tuning[-1]})')
    parser.add_argument(f'--{unit}', type=int, default=settings.default_count,
                        help=f'{unit} per sequence')
    parser.add_argument('--noise-config', type=Path, default=config / 'tracking_noise.yaml',
                        help='tracking-noise model fitted to the tracker (versioned YAML)')
    parser.add_argument('--noise-mae-deg', type=float,
                        help="overall mean absolute finger-joint error of the noise model, "
                        "degrees (default: the noise config's)")
    parser.add_argument('--tracker', action='store_true',
                        help='run the tracker on the rendered sequences instead of the noise '
                        'model (slow; tracked poses cached in data/scripted_tracking/)')
    parser.add_argument('--labels', choices=LABEL_SOURCES, default='segmented',
                        help="with --tracker: 'segmented' (colour segmentation of the "
                        "rendered images) or 'truth' (the renderer's labels)")
    parser.add_argument('--ungated', action='store_true',
                        help="with --tracker: every output of the tracker reaches the "
                        "consumer (core.pipeline.UNGATED), also the frames lookup_node and "
                        "ik_node refuse (cut by the image border, weak evidence, ...); "
                        "default: only the poses the nodes publish (NODE_LIMITS)")
    parser.add_argument('--database', type=Path,
                        help='with --tracker: pose database (default: the largest under data/; '
                        'tracked poses are cached per database contents)')
    parser.add_argument('--classifier', type=Path,
                        default=share_dir() / settings.classifier if settings.classifier
                        else None, help='trained classifier (colorglove_train_hand_classifiers; '
                        f'default: {settings.classifier or "none, the templates"})')
    parser.add_argument('--rules', action='store_true',
                        help='score with the hand-written rules / templates, no classifier')
    gate = settings.evidence_gate
    if gate is not None:
        parser.add_argument('--evidence-min-constraints', type=float,
                            help="with --tracker: skip frames whose tracker evidence (the "
                            "status line a node has) matched fewer constraints (0: off; "
                            f"default: the core's, {gate.min_constraints:g})")
        parser.add_argument('--evidence-max-reprojection-px', type=float,
                            help='with --tracker: skip frames whose reprojection error is '
                            f"larger (0: off; default: the core's, {gate.max_reprojection_px:g})")
    if settings.image_classifier is not None:
        parser.add_argument('--image-classifier',
                            help="with --tracker: a classifier of the frames' observation "
                            '(tiny image and blobs; feature set tiny_observation) combined '
                            'with the pose classifier (default: '
                            f'{settings.image_classifier or "none"}; "" = none)')
        parser.add_argument('--image-weight', type=float,
                            help="the image classifier's weight (default: the core's)")
    args = parser.parse_args(argv)
    from colorglove_ros.core.hand.pose_classifier import load_pose_classifier

    classifier = None if args.rules or args.classifier is None else load_pose_classifier(
        args.classifier, settings.feature_set)
    if args.tracker:
        database = args.database or find_database(data_dir())
        # tracked poses are cached under a tag of the database's contents
        limits = UNGATED if args.ungated else NODE_LIMITS
        source: Any = ScriptedTracker(database, config / 'ik.yaml', config / 'calibration.yaml',
                                      data_dir() / 'scripted_tracking', args.labels, limits)
        source_settings: dict[str, Any] = {'source': 'tracker', 'labels': args.labels,
                                           'database': str(database),
                                           'gates': 'ungated' if args.ungated else 'nodes'}
    else:
        noise = load_tracking_noise(args.noise_config)
        if args.noise_mae_deg is not None:
            noise = noise.with_joint_mae(args.noise_mae_deg)
        source, source_settings = noise, {'source': 'noise model',
                                          'noise_file': str(args.noise_config),
                                          'noise': asdict(noise)}
    source_settings['classifier'] = 'rules' if classifier is None else str(args.classifier)
    started = time.perf_counter()
    extra: dict[str, Any] = {}
    if gate is not None:
        given: dict[str, Any] = {}
        if args.evidence_min_constraints is not None:
            given['min_constraints'] = args.evidence_min_constraints
        if args.evidence_max_reprojection_px is not None:
            given['max_reprojection_px'] = args.evidence_max_reprojection_px or math.inf
        if given:
            extra['evidence'] = replace(gate, **given)
        source_settings['evidence_gate'] = asdict(extra.get('evidence', gate))
    image_path = None if settings.image_classifier is None else args.image_classifier
    if image_path is None and args.tracker and settings.image_classifier:
        image_path = str(share_dir() / settings.image_classifier)
    if image_path:
        from colorglove_ros.core.hand.observation_features import IMAGE_FEATURE_SETS

        # which of the image feature sets the evaluation reads, its detector checks
        extra['image_classifier'] = load_pose_classifier(image_path, IMAGE_FEATURE_SETS)
        source_settings['image_classifier'] = image_path
        if args.image_weight is not None:
            extra['image_weight'] = args.image_weight
            source_settings['image_weight'] = args.image_weight
    try:
        result = evaluate(args.seeds, getattr(args, unit), source, classifier, **extra)
    finally:
        if args.tracker:
            source.close()
    return ScriptedEvaluation(args, settings, source, source_settings, result,
                              time.perf_counter() - started)


def add_pipeline_arguments(parser: argparse.ArgumentParser, *, frames: int, seed: int,
                           sequence: str) -> None:
    """The arguments of the tools that run the node pipeline on a synthetic sequence (demo,
    benchmark, soak): its length and seed (``sequence`` names it in the help) and the pose
    database."""
    parser.add_argument('--frames', type=int, default=frames, help=f'frames of the {sequence}')
    parser.add_argument('--seed', type=int, default=seed, help=f'seed of the {sequence}')
    parser.add_argument('--database', type=Path,
                        help='pose database (default: the one config/database.yaml names)')


def _opencv_thread_count(text: str) -> int:
    """``--opencv-threads``' value: an integer from -1 to 64, as the nodes' parameter."""
    value = int(text)
    if not -1 <= value <= 64:
        raise argparse.ArgumentTypeError(f'{value} is not in -1..64')
    return value


def add_opencv_threads_argument(parser: argparse.ArgumentParser) -> None:
    """``--opencv-threads``: OpenCV's threads in the tool's process, defaulting to the nodes'
    ``opencv_threads`` (:data:`~colorglove_ros.core.opencv_threads.OPENCV_THREADS`), so that the
    process CPU a tool reports is what the node would take."""
    parser.add_argument('--opencv-threads', type=_opencv_thread_count, default=OPENCV_THREADS,
                        help='OpenCV threads of this process (cv2.setNumThreads), as the nodes\' '
                        f'opencv_threads parameter (default {OPENCV_THREADS}: every OpenCV call in '
                        'the calling thread; -1: OpenCV\'s own default, all cores)')


def tool_error(name: str, exc: Exception) -> int:
    """Report one of the package's errors (bad file, bad setting, bad input) as one line
    ``NAME: error: ...`` on stderr; return the tool's exit code 1."""
    print(f'{name}: error: {exc}', file=sys.stderr, flush=True)
    return 1


def run_tool(name: str, body: Callable[[], int]) -> int:
    """Run a tool's body; any of the package's own errors becomes :func:`tool_error`'s one
    line and exit code 1 instead of a traceback. SIGTERM and SIGHUP end the body like Ctrl-C
    does, through its ``finally`` blocks, so a tool that started nodes stops them instead of
    leaving them running (they run in sessions of their own and get no signal of the tool's;
    see :mod:`colorglove_ros.signal_exit`)."""
    with exit_on_signals():
        try:
            return body()
        except ColorGloveError as exc:
            return tool_error(name, exc)
