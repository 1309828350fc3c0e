"""Readable tables and JSON files for every evaluation and benchmark command."""
from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ['format_table', 'format_markdown_table', 'print_table', 'write_json']


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.4g}' if abs(value) < 1e5 else f'{value:.3e}'
    return str(value)


def format_table(rows: Sequence[Mapping[str, Any]], title: str = '') -> str:
    """Format rows (dicts sharing keys) as an aligned plain-text table."""
    if not rows:
        return f'{title}\n(no rows)' if title else '(no rows)'
    columns = list(rows[0].keys())
    for row in rows[1:]:
        columns += [key for key in row if key not in columns]
    cells = [[_cell(row.get(col, '')) for col in columns] for row in rows]
    widths = [max(len(col), *(len(r[i]) for r in cells)) for i, col in enumerate(columns)]
    lines = [title] if title else []
    lines.append('  '.join(col.ljust(w) for col, w in zip(columns, widths, strict=True)))
    lines.append('  '.join('-' * w for w in widths))
    lines += ['  '.join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    return '\n'.join(lines)


def format_markdown_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Format rows (dicts sharing keys) as a Markdown table, numbers as :func:`format_table`."""
    if not rows:
        return '(no rows)'
    columns = list(rows[0].keys())
    for row in rows[1:]:
        columns += [key for key in row if key not in columns]
    lines = ['| ' + ' | '.join(columns) + ' |', '|' + '---|' * len(columns)]
    lines += ['| ' + ' | '.join(_cell(row.get(col, '')) for col in columns) + ' |'
              for row in rows]
    return '\n'.join(lines)


def print_table(rows: Sequence[Mapping[str, Any]], title: str = '') -> None:
    """Print rows as a table (see :func:`format_table`)."""
    print(format_table(rows, title), flush=True)


def _jsonable(value: Any) -> Any:
    if hasattr(value, 'tolist'):
        return value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    return value


def write_json(path: str | Path, figures: Mapping[str, Any]) -> Path:
    """Write figures (tables as lists of dicts, scalars, numpy arrays) as indented JSON."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_jsonable(figures), indent=2, sort_keys=False) + '\n')
    return path
