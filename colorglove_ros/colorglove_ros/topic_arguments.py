"""``TOPIC=VALUE`` command-line arguments (the latency probe's ``--stage-topics``, play_bag's
``--wait-for``), read one way: topic names hold no ``=``, so the first one splits."""
from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import TypeVar

__all__ = ['topic_argument']

Value = TypeVar('Value')


def topic_argument(value_name: str, convert: Callable[[str], Value]
                   ) -> Callable[[str], tuple[str, Value]]:
    """An argparse ``type`` reading ``TOPIC=<value_name>`` as (topic, ``convert(value)``); an
    empty side, a missing ``=`` or a value ``convert`` refuses (ValueError) is an
    ``ArgumentTypeError`` naming the expected form."""
    def parse(text: str) -> tuple[str, Value]:
        topic, sep, value = text.partition('=')
        try:
            if sep and topic and value:
                return topic, convert(value)
        except ValueError:
            pass
        raise argparse.ArgumentTypeError(f'expected TOPIC={value_name}, got {text!r}')
    return parse
