"""What every command-line tool shares: its parser with ``--json``, and one error policy."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from colorglove_ros.core.errors import ColorGloveError

__all__ = ['tool_parser', 'add_sequence_arguments', 'add_scripted_noise_arguments', 'run_tool']


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


def add_sequence_arguments(parser: argparse.ArgumentParser, *, sequences_help: str,
                           labels: tuple[str, ...], labels_help: str) -> None:
    """The arguments of the tools that run the tracker over synthetic sequences (eval_ik,
    learn_ik_covariances): database, sequences, frames, label source, colour, IK and camera
    configuration, frame rate."""
    from colorglove_ros.paths import share_dir

    config = share_dir() / 'config'
    parser.add_argument('--database', help='pose database directory (default: the largest '
                        'under data/)')
    parser.add_argument('--sequences', type=int, default=4, help=sequences_help)
    parser.add_argument('--frames', type=int, default=150, help='frames per sequence')
    parser.add_argument('--labels', choices=labels, default='truth', help=labels_help)
    parser.add_argument('--color-config', help='colour calibration YAML for --labels '
                        'segmented (default config/color_calibration.yaml)')
    parser.add_argument('--ik-config', default=str(config / 'ik.yaml'))
    parser.add_argument('--calibration', default=str(config / 'calibration.yaml'),
                        help='camera rig the tracker runs with')
    parser.add_argument('--fps', type=float, default=30.0)


def add_scripted_noise_arguments(parser: argparse.ArgumentParser, *, default_seeds: list[int],
                                 tuning_seeds: list[int]) -> None:
    """The arguments of the evaluations on scripted poses with a tracking-noise model
    (eval_gestures, eval_spelling): held-out seeds and the noise level."""
    parser.add_argument('--seeds', type=int, nargs='+', default=list(default_seeds),
                        help=f'sequence seeds (tuning used {tuning_seeds[0]}-{tuning_seeds[-1]})')
    parser.add_argument('--noise-mae-deg', type=float, default=7.0,
                        help='mean absolute finger-joint error of the noise model, degrees')


def run_tool(name: str, body: Callable[[], int]) -> int:
    """Run a tool's body; any of the package's own errors (bad file, bad setting, bad input)
    becomes one line ``NAME: error: ...`` on stderr and exit code 1 instead of a traceback."""
    try:
        return body()
    except ColorGloveError as exc:
        print(f'{name}: error: {exc}', file=sys.stderr, flush=True)
        return 1
