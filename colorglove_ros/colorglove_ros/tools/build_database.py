"""Build the pose database: sample, render, crop, learn codes, save (see config/database.yaml)."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

from tqdm import tqdm

from colorglove_ros.core.lookup.database import DatabaseError, save_database
from colorglove_ros.core.lookup.database_build import (
    BuildConfig,
    build_database,
    read_database_config,
    retrain_codes,
)
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.paths import share_dir
from colorglove_ros.tools._cli import tool_error, tool_parser

__all__ = ['main', 'load_build_config', 'DEFAULT_CONFIG']

DEFAULT_CONFIG = share_dir() / 'config' / 'database.yaml'


def load_build_config(path: str | Path = DEFAULT_CONFIG) -> tuple[BuildConfig, Path, dict]:
    """Build parameters, default database path and lookup parameters from the YAML."""
    return read_database_config(path)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = tool_parser(__doc__)
    parser.add_argument('--config', default=str(DEFAULT_CONFIG), help='database YAML')
    parser.add_argument('--entries', type=int, help='number of entries (default from config)')
    parser.add_argument('--output', help='database directory (default from config)')
    parser.add_argument('--orientations', type=int, help='orientations per configuration')
    parser.add_argument('--bits', type=int, help='code length')
    parser.add_argument('--pairs', type=int, help='SSC training pairs')
    parser.add_argument('--seed', type=int, help='sampling seed')
    parser.add_argument('--retrain-codes', action='store_true',
                        help='only learn new codes for the existing database at --output')
    parser.add_argument('--named-shape-configs', type=int,
                        help='configurations picked first among the named shapes (letters, '
                        'gestures) and their noisy copies')
    parser.add_argument('--pinch-shapes', action='store_true', default=None,
                        help='add the pinches of the middle, ring and little fingers to the '
                        "collection's named shapes (core/hand/poses.py PINCH_SHAPES)")
    parser.add_argument('--training-images', type=int,
                        help='images the SSC training pairs are drawn from')
    args = parser.parse_args(argv)
    config, db_path, _ = load_build_config(args.config)
    overrides = {'entries': args.entries, 'orientations_per_config': args.orientations,
                 'num_bits': args.bits, 'num_pairs': args.pairs, 'seed': args.seed,
                 'training_images': args.training_images,
                 'named_shape_configs': args.named_shape_configs,
                 'pinch_shapes': args.pinch_shapes}
    config = dataclasses.replace(config, **{k: v for k, v in overrides.items() if v is not None})
    output = Path(args.output) if args.output else db_path
    t0 = time.perf_counter()
    if args.retrain_codes:
        try:
            enc = retrain_codes(output, config.num_bits, config.num_pairs, config.seed,
                                config.training_images)
        except DatabaseError as exc:
            return tool_error('colorglove_build_database', exc)
        row = {'database': str(output), 'bits': enc.num_bits, 'pairs': config.num_pairs,
               'training_images': config.training_images,
               'seconds': time.perf_counter() - t0}
        print_table([row], 'codes retrained')
        if args.json:
            write_json(args.json, {'retrain': row})
        return 0
    try:
        db = build_database(config, progress=lambda msg: tqdm.write(f'[build] {msg}'),
                            bar=lambda it, **kw: tqdm(it, **kw))
        t1 = time.perf_counter()
        save_database(db, output)
    except DatabaseError as exc:
        return tool_error('colorglove_build_database', exc)
    t2 = time.perf_counter()
    timings = db.meta.get('timings', {})
    rows = [{'entries': len(db), 'configs': db.meta['num_configs'], 'bits': db.num_bits,
             'sampling_s': timings.get('sampling_s', 0.0), 'render_s': timings.get('render_s', 0.0),
             'assemble_s': timings.get('assemble_s', 0.0), 'save_s': t2 - t1,
             'total_s': t2 - t0, 'size_MB': db.nbytes / 1e6,
             'dispersion_mm': 1e3 * db.meta['dispersion_m']}]
    print_table(rows, f'pose database -> {output}')
    if args.json:
        write_json(args.json, {'build': rows[0], 'output': str(output)})
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
