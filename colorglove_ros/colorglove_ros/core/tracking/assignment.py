"""``linear_sum_assignment`` (scipy's compiled solver) without importing ``scipy.optimize``.

Importing ``scipy.optimize`` loads most of SciPy (linear programming, FFT, special functions)
and takes much of a respawned IK node's start-up, which needs only the assignment solver. The
solver is a self-contained compiled module, ``scipy/optimize/_lsap``, loaded here from its file
alone. If a SciPy release moves it, the public import is used instead (slower start-up, same
answers); the test suite checks that the pinned SciPy takes the direct path.
"""
from __future__ import annotations

import importlib.machinery
import importlib.util
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np
import scipy

__all__ = ['linear_sum_assignment', 'LOADED_DIRECTLY']

_MODULE = 'scipy.optimize._lsap'


def _load_compiled_solver() -> ModuleType | None:
    """The compiled ``_lsap`` module loaded from its file, or None when it is not there."""
    folder = Path(scipy.__file__).parent / 'optimize'
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = folder / f'_lsap{suffix}'
        if path.is_file():
            loader = importlib.machinery.ExtensionFileLoader(_MODULE, str(path))
            spec = importlib.util.spec_from_file_location(_MODULE, path, loader=loader)
            if spec is None:
                return None
            module = importlib.util.module_from_spec(spec)
            loader.exec_module(module)
            return module
    return None


_compiled = _load_compiled_solver()
LOADED_DIRECTLY = _compiled is not None
"""Whether the solver came from the compiled module alone (not ``scipy.optimize``)."""

if _compiled is not None:
    _solver: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] = \
        _compiled.linear_sum_assignment
else:                                       # pragma: no cover - another SciPy layout
    from scipy.optimize import linear_sum_assignment as _solver


def linear_sum_assignment(cost: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the least-cost one-to-one assignment of a 2-D ``cost`` matrix, as
    ``scipy.optimize.linear_sum_assignment``."""
    return _solver(np.asarray(cost, np.float64))
