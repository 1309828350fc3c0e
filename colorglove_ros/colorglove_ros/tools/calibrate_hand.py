"""Calibrate the user's hand from measurements: hand length and one length factor per digit,
written into the calibration YAML every node reads (``hand_length_m``,
``finger_length_factors``; the cameras are kept).

Measure the right hand lying flat, fingers straight and together, with a ruler (mm):

  --hand-length-mm  from the wrist crease (the palm-side crease nearest the palm) to the tip
                    of the middle finger.
  --finger-mm T I M R L
                    each digit (thumb, index, middle, ring, little) from the top of its base
                    knuckle to its tip, on the back of the hand. A finger's base knuckle is the
                    one where it joins the hand (the knuckle that stands out in a fist, the
                    third from the tip); the thumb's is where it leaves the palm (its second
                    knuckle from the tip), not the wrist.

A digit's factor multiplies the model's own phalanx lengths (``nominal_mm``: the model's
knuckle-to-tip length at this hand length); the whole hand is then scaled to keep the measured
hand length, so a long middle finger leaves a smaller palm (``palm_scale``) and every factor
is its digit's measured-to-nominal ratio divided by that scale. Lengths far from the model's
(factors outside the allowed range) are refused as measurement errors.
"""
from __future__ import annotations

import os
import re
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import yaml

from colorglove_ros.core.camera import (
    CALIBRATION_VERSION,
    CAMERA_INFO_YAML_KEYS,
    CalibrationError,
    load_calibration,
)
from colorglove_ros.core.conventions import (
    DEFAULT_HAND_LENGTH_M,
    FINGER_LENGTH_FACTOR_RANGE,
    HAND_LENGTH_RANGE_M,
)
from colorglove_ros.core.hand.model import (
    DIGITS,
    HandModel,
    calibrated_hand_model,
    finger_length_factors_for,
)
from colorglove_ros.core.report import print_table, write_json
from colorglove_ros.core.yaml_io import load_yaml_mapping
from colorglove_ros.paths import share_dir
from colorglove_ros.tools._cli import run_tool, tool_parser

__all__ = ['HandMeasurementError', 'factors_from_measurements', 'updated_calibration_text',
           'main']

TOOL_NAME = 'colorglove_calibrate_hand'
FACTOR_DECIMALS = 4
"""Decimals of the factors written (a digit length to about 0.01 mm)."""
HAND_LENGTH_DECIMALS = 5
"""Decimals of the hand length written, metres."""


class HandMeasurementError(CalibrationError):
    """Hand measurements that are not a hand's (out of range, a finger longer than the hand,
    a digit too far from the model's proportions)."""


def factors_from_measurements(hand_length_mm: float, finger_mm: list[float]
                              ) -> tuple[float, tuple[float, ...]]:
    """(hand length in m, rounded finger length factors) from the measurements in mm; raise
    :class:`HandMeasurementError` naming the measurement that is not plausible."""
    low, high = HAND_LENGTH_RANGE_M
    hand_length_m = round(float(hand_length_mm) / 1000.0, HAND_LENGTH_DECIMALS)
    if not low < hand_length_m < high:
        raise HandMeasurementError(
            f'--hand-length-mm {hand_length_mm} is not a human hand (wrist crease to middle '
            f'fingertip: between {low * 1000:g} and {high * 1000:g} mm)')
    if len(finger_mm) != len(DIGITS) or not all(0.0 < float(v) < float('inf')
                                                 for v in finger_mm):
        raise HandMeasurementError(f'--finger-mm needs {len(DIGITS)} positive lengths '
                                   f'({", ".join(DIGITS)}), got {finger_mm}')
    lengths_m = [float(v) / 1000.0 for v in finger_mm]
    middle = DIGITS.index('middle')
    if lengths_m[middle] >= hand_length_m:
        raise HandMeasurementError(
            f'the middle finger ({finger_mm[middle]} mm, knuckle to tip) must be shorter than '
            f'the hand ({hand_length_mm} mm, wrist crease to the middle fingertip)')
    factors = finger_length_factors_for(hand_length_m, lengths_m)
    nominal_mm = HandModel(hand_length_m).digit_lengths_m * 1000.0
    f_low, f_high = FINGER_LENGTH_FACTOR_RANGE
    for digit, factor, measured, nominal in zip(DIGITS, factors, finger_mm, nominal_mm,
                                                strict=True):
        if not f_low <= factor <= f_high:
            raise HandMeasurementError(
                f'the {digit} ({measured} mm, knuckle to tip) is {factor:.2f} times the '
                f"model's {nominal:.1f} mm for a {hand_length_mm} mm hand; allowed "
                f'{f_low}-{f_high} times: check the measurement (see --help)')
    return hand_length_m, tuple(round(f, FACTOR_DECIMALS) for f in factors)


def _top_level_line(key: str) -> re.Pattern[str]:
    """A top-level block-style ``key: value  # comment`` line."""
    return re.compile(rf'^{key}:[ \t]*(?P<value>[^#\n]*?)[ \t]*(?P<comment>#[^\n]*)?$',
                      re.MULTILINE)


def updated_calibration_text(text: str, hand_length_m: float,
                             factors: tuple[float, ...]) -> tuple[str, bool]:
    """The calibration YAML ``text`` with ``hand_length_m`` and ``finger_length_factors`` set,
    and whether its comments and layout were kept (a top-level line edit that reads back as
    intended) or the mapping had to be written afresh (comments lost)."""
    data = yaml.safe_load(text)
    wanted = {**data, 'hand_length_m': hand_length_m,
              'finger_length_factors': [float(f) for f in factors]}
    values = {'hand_length_m': repr(hand_length_m),
              'finger_length_factors': '[' + ', '.join(repr(float(f)) for f in factors) + ']'}
    edited = text if text.endswith('\n') else text + '\n'
    anchor = 'version'
    for key, value in values.items():
        pattern = _top_level_line(key)
        found = pattern.search(edited)
        if found is not None:
            comment = f'  {found["comment"]}' if found['comment'] else ''
            edited = edited[:found.start()] + f'{key}: {value}{comment}' + edited[found.end():]
        else:
            before = _top_level_line(anchor).search(edited)
            if before is None:
                break
            edited = edited[:before.end()] + f'\n{key}: {value}' + edited[before.end():]
        anchor = key
    try:
        kept = yaml.safe_load(edited) == wanted
    except yaml.YAMLError:
        kept = False
    if kept:
        return edited, True
    return yaml.safe_dump(wanted, sort_keys=False, default_flow_style=None), False


def _source_text(target: Path, cameras_from: Path) -> tuple[str, Path]:
    """The YAML text to update and the file it came from: ``target`` when it exists, else a
    new file holding the cameras of ``cameras_from`` (own format, or a camera_info YAML that
    the new file names in ``camera_info_file``)."""
    source = target if target.exists() else cameras_from
    data = load_yaml_mapping(source, CalibrationError, 'calibration file')
    load_calibration(source)          # refuse a calibration the nodes would refuse
    if all(key in data for key in CAMERA_INFO_YAML_KEYS):
        if source == target:
            raise CalibrationError(
                f'{target} is a camera_info YAML (camera_calibration\'s format), which holds no '
                'hand; write a new calibration file instead (--calibration NEW.yaml '
                f'--cameras-from {target})')
        entry = {'camera_info_file': str(source.resolve())}
        return yaml.safe_dump({'version': CALIBRATION_VERSION, 'cameras': [entry]},
                              sort_keys=False), source
    return source.read_text(), source


def _write_atomically(path: Path, text: str) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile('w', dir=path.parent, suffix='.yaml',
                                         delete=False) as tmp:
            tmp.write(text)
        os.replace(tmp.name, path)
    except OSError as exc:
        raise CalibrationError(f'cannot write {path}: {exc}') from exc


def _description() -> str:
    """The module docstring plus the model's own digit lengths and the allowed factors."""
    model = HandModel(DEFAULT_HAND_LENGTH_M)
    lengths = ', '.join(f'{digit} {length * 1000:.1f}'
                        for digit, length in zip(DIGITS, model.digit_lengths_m, strict=True))
    low, high = FINGER_LENGTH_FACTOR_RANGE
    return (f"{__doc__}\nThe model's own knuckle-to-tip lengths for a "
            f'{DEFAULT_HAND_LENGTH_M * 1000:g} mm hand (they scale with the hand length): '
            f'{lengths} mm. Allowed factors: {low}-{high}.\n')


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = tool_parser(_description(), raw_description=True,
                         json_help='also write the measurements, factors and model lengths to '
                                   'this JSON file')
    parser.add_argument('--calibration', type=Path, required=True,
                        help='calibration YAML to update (its cameras and comments are kept); '
                             'created from --cameras-from when it does not exist')
    parser.add_argument('--cameras-from', type=Path,
                        default=share_dir() / 'config' / 'calibration.yaml',
                        help='calibration (or camera_info) YAML whose cameras a new '
                             '--calibration file gets (default: the package\'s '
                             'config/calibration.yaml)')
    parser.add_argument('--hand-length-mm', type=float, required=True, metavar='MM',
                        help='wrist crease to middle fingertip, hand flat')
    parser.add_argument('--finger-mm', type=float, nargs=len(DIGITS), required=True,
                        metavar=tuple(d[0].upper() for d in DIGITS),
                        help='base knuckle to tip of the thumb, index, middle, ring and '
                             'little finger (see above)')
    parser.add_argument('--dry-run', action='store_true',
                        help='print the calibration, write no file')
    args = parser.parse_args(argv)

    def body() -> int:
        hand_length_m, factors = factors_from_measurements(args.hand_length_mm, args.finger_mm)
        text, source = _source_text(args.calibration, args.cameras_from)
        new_text, comments_kept = updated_calibration_text(text, hand_length_m, factors)
        if args.dry_run:
            calibration = replace(load_calibration(source), hand_length_m=hand_length_m,
                                  finger_length_factors=factors)
        else:
            _write_atomically(args.calibration, new_text)
            calibration = load_calibration(args.calibration)
            if calibration.finger_length_factors != factors \
                    or calibration.hand_length_m != hand_length_m:
                raise CalibrationError(f'{args.calibration} does not read back as written')
        model = calibrated_hand_model(calibration)
        standard = HandModel(hand_length_m)
        nominal_mm = standard.digit_lengths_m * 1000.0
        palm_scale = model.scale / standard.scale
        rows: list[dict[str, Any]] = [
            {'digit': digit, 'measured_mm': float(measured), 'nominal_mm': float(nominal),
             'factor': factor, 'model_mm': float(fitted)}
            for digit, measured, nominal, factor, fitted in zip(
                DIGITS, args.finger_mm, nominal_mm, factors, model.digit_lengths_m * 1000.0,
                strict=True)]
        action = 'would write' if args.dry_run else 'wrote'
        print_table(rows, title=f'hand length {hand_length_m * 1000:.1f} mm (wrist to middle '
                                f'fingertip); digit lengths base knuckle to tip')
        print(f'palm and finger widths x{palm_scale:.4f} of the model\'s at this hand length '
              '(the middle finger takes the rest of the hand length)')
        print(f'{action} {args.calibration} (cameras from {source}'
              f'{"" if comments_kept else "; comments not kept: the file was rewritten"})')
        if args.json is not None:
            write_json(args.json, {
                'calibration': str(args.calibration), 'written': not args.dry_run,
                'cameras_from': str(source), 'comments_kept': comments_kept,
                'hand_length_m': hand_length_m, 'finger_length_factors': list(factors),
                'palm_scale': palm_scale, 'digits': rows})
        return 0

    return run_tool(TOOL_NAME, body)


if __name__ == '__main__':
    raise SystemExit(main())
