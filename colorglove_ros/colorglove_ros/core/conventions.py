"""Constants shared by every stage, defined once: glove layout, tiny-image size, default hand."""
from __future__ import annotations

__all__ = ['NUM_COLORS', 'NUM_PATCHES', 'TINY_SIZE', 'DEFAULT_HAND_LENGTH_M', 'DEFAULT_GLOVE_SEED',
           'HAND_LENGTH_RANGE_M', 'MODEL_HAND_LENGTH_RANGE_M', 'FINGER_LENGTH_FACTOR_RANGE']

NUM_COLORS = 10
"""Glove colours, labels 1..10 in label images; 0 is background."""
NUM_PATCHES = 20
"""Printed patches on the glove (each one of the ``NUM_COLORS`` colours)."""
TINY_SIZE = 40
"""Side in pixels of the tiny label image the lookup compares (paper section 4)."""
DEFAULT_HAND_LENGTH_M = 0.19
"""Hand length (wrist crease to middle fingertip, metres) used when none is configured."""
DEFAULT_GLOVE_SEED = 0
"""Seed of the standard glove's patch layout (a database records the one it was built with)."""
HAND_LENGTH_RANGE_M = (0.08, 0.35)
"""Wrist-crease-to-middle-fingertip lengths of human hands a calibration may give (m)."""
MODEL_HAND_LENGTH_RANGE_M = (0.05, 0.4)
"""Hand lengths (m) the kinematic model and the database builder are made for (wider than
``HAND_LENGTH_RANGE_M``: also test and toy hands)."""
FINGER_LENGTH_FACTOR_RANGE = (0.7, 1.3)
"""Per-digit length factors (a user's digit over the model's nominal proportions) a hand model
and a calibration accept; beyond them a measurement is wrong, not a hand."""
