"""Read YAML files that must hold a mapping, with errors of the caller's type naming the file."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ['load_yaml_mapping']


def load_yaml_mapping(path: str | Path, error: type[Exception], what: str) -> dict[str, Any]:
    """The mapping in YAML file ``path``; raise ``error`` if it is missing, not valid YAML or
    not a mapping. ``what`` names the file in messages (e.g. 'calibration file')."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError as exc:
        raise error(f'{what} not found: {path}') from exc
    except UnicodeDecodeError as exc:
        raise error(f'{what} is not text (binary or another encoding): {path}: {exc}') from exc
    except OSError as exc:
        raise error(f'{what} cannot be read: {path}: {exc}') from exc
    except yaml.YAMLError as exc:
        raise error(f'{what} is not valid YAML: {path}: {exc}') from exc
    if not isinstance(data, dict):
        raise error(f'{what} {path} does not hold a mapping')
    return data
