"""What every command-line tool shares: its parser with ``--json``, and one error policy."""
from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from colorglove_ros.core.errors import ColorGloveError

__all__ = ['tool_parser', 'run_tool']


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


def run_tool(name: str, body: Callable[[], int]) -> int:
    """Run a tool's body; any of the package's own errors (bad file, bad setting, bad input)
    becomes one line ``NAME: error: ...`` on stderr and exit code 1 instead of a traceback."""
    try:
        return body()
    except ColorGloveError as exc:
        print(f'{name}: error: {exc}', file=sys.stderr, flush=True)
        return 1
