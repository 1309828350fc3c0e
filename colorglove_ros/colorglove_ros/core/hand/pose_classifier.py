"""A small classifier of hand shapes from the tracked pose, trained on synthetic data.

Features (:func:`pose_features`), all in the hand's wrist frame and scale-free: the 20 finger
joint angles (rad); the 10 distances between the five fingertips (thumb tip to each fingertip
first) over the hand length; the 20 keypoints after the wrist (MediaPipe order,
``core/hand/keypoints.py``) over the hand length, which place the thumb relative to the
fingers; and, for letters (``with_direction``), the direction the fingers point in the camera
frame (``core/hand/spelling.py`` ``pointing_direction``: G, H, P, Q differ from other letters
by it).

Model (:data:`MODEL_KINDS`): the features standardised, then either one hidden layer of ReLU
units and a softmax over the classes (``mlp``: a multi-layer perceptron fitted by scikit-learn
with a seeded initialisation), a linear layer and a softmax (``lda``: linear discriminant
analysis, each class a Gaussian with a covariance shared by all classes, shrunk by the
Ledoit-Wolf estimate, so few and correlated samples still give a stable fit), or a quadratic
layer and a softmax (``qda``: regularised discriminant analysis, each class a Gaussian with its
own Ledoit-Wolf covariance blended with the shared one, ``covariance_blend`` the shared share:
1 is the ``lda``, 0 a plain quadratic discriminant; a tracker whose error depends on the hand
shape gives each class its own spread), kept as plain arrays, so running it needs numpy only.
The same models also classify the image evidence of a frame
(``core/hand/observation_features.py``, feature set ``tiny_observation``).
Files are ``.npz`` with a format name and version (:data:`CLASSIFIER_FORMAT`,
:data:`CLASSIFIER_FORMAT_VERSION`; version 1, without the quadratic layer, is still read), the
classes, the feature set and a line saying how the model was trained.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.hand.model import NUM_DOFS, HandModel, rotvec_to_matrix
from colorglove_ros.core.hand.observation_features import IMAGE_FEATURE_SETS

__all__ = ['CLASSIFIER_FORMAT', 'CLASSIFIER_FORMAT_VERSION', 'FEATURE_SETS', 'MODEL_KINDS',
           'ClassifierError', 'PoseClassifier', 'pose_features', 'train_pose_classifier',
           'save_pose_classifier', 'load_pose_classifier', 'add_image_log_proba']

CLASSIFIER_FORMAT = 'colorglove_pose_classifier'
CLASSIFIER_FORMAT_VERSION = 2     # 2: an optional quadratic layer (``qda``)
_READABLE_VERSIONS = (1, 2)
# feature set name -> whether it includes the pointing direction
FEATURE_SETS: dict[str, bool] = {'hand_shape': False, 'hand_shape_direction': True}
MODEL_KINDS: tuple[str, ...] = ('mlp', 'lda', 'qda')
_TIPS = np.array([4, 8, 12, 16, 20])
_PAIRS = np.triu_indices(5, 1)


class ClassifierError(ColorGloveError, ValueError):
    """A bad classifier file, feature set or input."""


def _pointing(Q: np.ndarray) -> np.ndarray:
    """(N, 3) directions the fingers point in the camera frame (the hand frame's -y axis)."""
    return -np.stack([rotvec_to_matrix(q[3:6])[:, 1] for q in Q])


def pose_features(model: HandModel, poses: np.ndarray, feature_set: str) -> np.ndarray:
    """(N, F) features (module docstring) of poses (N, 26) or (F,) of one pose (26,)."""
    if feature_set not in FEATURE_SETS:
        raise ClassifierError(f'unknown feature set {feature_set!r}, expected one of '
                              f'{tuple(FEATURE_SETS)}')
    Q = np.asarray(poses, dtype=float)
    single = Q.ndim == 1
    Q = np.atleast_2d(Q)
    if Q.shape[1] != NUM_DOFS or not np.all(np.isfinite(Q)):
        raise ClassifierError(f'poses must be finite (N, 26), got shape {Q.shape}')
    local = Q.copy()
    local[:, 0:6] = 0.0                      # the hand frame at the camera origin: wrist frame
    points = model.keypoints_batch(local) / model.hand_length_m
    tips = points[:, _TIPS]
    distances = np.linalg.norm(tips[:, _PAIRS[0]] - tips[:, _PAIRS[1]], axis=-1)
    parts = [Q[:, 6:], distances, points[:, 1:].reshape(len(Q), -1)]
    if FEATURE_SETS[feature_set]:
        parts.append(_pointing(Q))
    out = np.concatenate(parts, axis=1)
    return out[0] if single else out


@dataclass(frozen=True)
class PoseClassifier:
    """A trained classifier (module docstring): ``classes``, the ``feature_set``, the
    standardisation (``mean``, ``scale``), the layers' weights and biases, ``source`` (how it
    was trained) and, for a one-layer model, an optional ``quadratic`` (C, F, F): class c's
    score then loses half of ``x @ quadratic[c] @ x`` of the standardised features ``x``."""

    classes: tuple[str, ...]
    feature_set: str
    mean: np.ndarray
    scale: np.ndarray
    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    source: str = ''
    quadratic: np.ndarray | None = None

    def log_proba(self, features: np.ndarray) -> np.ndarray:
        """Log class probabilities, (C,) for features (F,) or (N, C) for (N, F)."""
        x = (np.asarray(features, dtype=float) - self.mean) / self.scale
        standardised = x
        for k, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = x @ w + b
            if k < len(self.weights) - 1:
                x = np.maximum(x, 0.0)
        if self.quadratic is not None:
            spread = np.tensordot(standardised, self.quadratic, axes=([-1], [1]))
            x = x - 0.5 * (spread * standardised[..., None, :]).sum(axis=-1)
        x = x - x.max(axis=-1, keepdims=True)
        return x - np.log(np.exp(x).sum(axis=-1, keepdims=True))

    def pose_log_proba(self, model: HandModel, q: np.ndarray) -> np.ndarray:
        """Log class probabilities (C,) of one pose (26,)."""
        return self.log_proba(pose_features(model, q, self.feature_set))


def add_image_log_proba(log_p: np.ndarray, classes: Sequence[str],
                        image_classifier: PoseClassifier, observations: np.ndarray,
                        weight: float) -> np.ndarray:
    """(N, C) ``log_p`` (class log-probabilities of N frames in ``classes`` order) plus
    ``weight`` times ``image_classifier``'s log-probabilities of the frames' observation
    features (N, F), in the same order: a product of the two classifiers' probabilities (the
    image one's raised to the weight), not normalised."""
    log_p = np.atleast_2d(np.asarray(log_p, dtype=float))
    observations = np.atleast_2d(np.asarray(observations, dtype=float))
    if len(observations) != len(log_p):
        raise ClassifierError(f'{len(log_p)} frames but {len(observations)} observations')
    try:
        order = [image_classifier.classes.index(c) for c in classes]
    except ValueError as exc:
        raise ClassifierError(f'the image classifier lacks a class of {tuple(classes)}: '
                              f'{image_classifier.classes}') from exc
    return log_p + weight * np.atleast_2d(image_classifier.log_proba(observations))[:, order]


def _shrunk_covariance(x: np.ndarray) -> np.ndarray:
    """The Ledoit-Wolf covariance of rows ``x``, estimated on their standardised columns and
    scaled back (as scikit-learn's discriminant analysis with ``shrinkage='auto'``)."""
    from sklearn.covariance import ledoit_wolf

    scale = x.std(axis=0)
    scale[scale < 1e-12] = 1.0
    return scale[:, None] * ledoit_wolf((x - x.mean(axis=0)) / scale)[0] * scale[None, :]


def _quadratic_discriminant(x: np.ndarray, labels: np.ndarray, classes: np.ndarray,
                            blend: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weights (F, C), biases (C,) and quadratic layer (C, F, F) of the regularised quadratic
    discriminant of standardised rows ``x``: class c a Gaussian of its mean and covariance
    ``(1 - blend) S_c + blend S``, S_c the class's Ledoit-Wolf covariance, S their
    prior-weighted mean (the ``lda``'s shared covariance), priors the class shares."""
    members = [labels == c for c in classes]
    priors = np.array([m.mean() for m in members])
    means = [x[m].mean(axis=0) for m in members]
    covariances = [_shrunk_covariance(x[m]) for m in members]
    shared = sum(p * c for p, c in zip(priors, covariances, strict=True))
    weights, biases, quadratic = [], [], []
    for prior, mu, cov in zip(priors, means, covariances, strict=True):
        blended = (1.0 - blend) * cov + blend * shared
        precision = np.linalg.inv(blended)
        precision = 0.5 * (precision + precision.T)
        _, log_det = np.linalg.slogdet(blended)
        weights.append(precision @ mu)
        biases.append(-0.5 * mu @ precision @ mu - 0.5 * log_det + np.log(prior))
        quadratic.append(precision)
    return np.stack(weights, axis=1), np.array(biases), np.stack(quadratic)


def train_pose_classifier(features: np.ndarray, labels: np.ndarray, feature_set: str,
                          hidden: int = 64, alpha: float = 1e-3, seed: int = 0,
                          source: str = '', max_iter: int = 200, kind: str = 'mlp',
                          covariance_blend: float = 0.5) -> PoseClassifier:
    """Fit the classifier of ``kind`` (:data:`MODEL_KINDS`) to labelled feature rows. ``mlp``:
    ``hidden`` units, L2 penalty ``alpha``, seeded (deterministic for a seed), stops when a
    tenth of the rows held out for validation stops improving; ``lda``: deterministic, the
    other settings unused; ``qda``: deterministic, ``covariance_blend`` (0-1) the shared
    covariance's share in each class's."""
    features = np.asarray(features, dtype=float)
    labels = np.asarray(labels).astype(str)
    classes = np.unique(labels)
    if len(classes) < 3:
        raise ClassifierError(f'need at least 3 classes, got {len(classes)}')
    if kind not in MODEL_KINDS:
        raise ClassifierError(f'unknown classifier kind {kind!r}, expected one of {MODEL_KINDS}')
    mean = features.mean(axis=0)
    scale = features.std(axis=0)
    scale[scale < 1e-9] = 1.0
    x = (features - mean) / scale
    if kind == 'qda':
        if not 0.0 <= covariance_blend <= 1.0:
            raise ClassifierError(f'covariance_blend must be in [0, 1], got {covariance_blend}')
        w, b, quadratic = _quadratic_discriminant(x, labels, classes, covariance_blend)
        return PoseClassifier(tuple(str(c) for c in classes), feature_set, mean, scale, (w,),
                              (b,), source, quadratic)
    if kind == 'lda':
        from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

        lda = LinearDiscriminantAnalysis(solver='lsqr', shrinkage='auto').fit(x, labels)
        return PoseClassifier(tuple(str(c) for c in lda.classes_), feature_set, mean, scale,
                              (np.asarray(lda.coef_.T),), (np.asarray(lda.intercept_),), source)
    from sklearn.neural_network import MLPClassifier

    mlp = MLPClassifier((hidden,), alpha=alpha, max_iter=max_iter, random_state=seed,
                        early_stopping=True, validation_fraction=0.1, n_iter_no_change=8)
    mlp.fit(x, labels)
    return PoseClassifier(tuple(str(c) for c in mlp.classes_), feature_set, mean, scale,
                          tuple(np.asarray(w) for w in mlp.coefs_),
                          tuple(np.asarray(b) for b in mlp.intercepts_), source)


def save_pose_classifier(path: str | Path, classifier: PoseClassifier) -> Path:
    """Write the classifier as a versioned ``.npz``."""
    path = Path(path)
    arrays = {f'weights_{k}': w for k, w in enumerate(classifier.weights)}
    arrays.update({f'biases_{k}': b for k, b in enumerate(classifier.biases)})
    with path.open('wb') as f:
        np.savez_compressed(f, format=np.array(CLASSIFIER_FORMAT),
                            version=np.array(CLASSIFIER_FORMAT_VERSION),
                            classes=np.array(classifier.classes),
                            feature_set=np.array(classifier.feature_set),
                            source=np.array(classifier.source), mean=classifier.mean,
                            scale=classifier.scale, layers=np.array(len(classifier.weights)),
                            quadratic=np.zeros(0) if classifier.quadratic is None
                            else classifier.quadratic, **arrays)
    return path


def load_pose_classifier(path: str | Path,
                         feature_set: str | tuple[str, ...] | None = None) -> PoseClassifier:
    """Read a classifier file (format version 1 or 2); :class:`ClassifierError` if it is
    missing, of another format or version, inconsistent, or (given ``feature_set``: one set's
    name, or a tuple of the sets accepted) made for other features."""
    try:
        with np.load(Path(path), allow_pickle=False) as data:
            version = int(data['version'])
            if str(data['format']) != CLASSIFIER_FORMAT or version not in _READABLE_VERSIONS:
                raise ClassifierError(f'{path} is not a {CLASSIFIER_FORMAT} file of version '
                                      f'{" or ".join(map(str, _READABLE_VERSIONS))}')
            layers = int(data['layers'])
            quadratic = data['quadratic'] if version >= 2 else np.zeros(0)
            clf = PoseClassifier(tuple(str(c) for c in data['classes']),
                                 str(data['feature_set']), data['mean'], data['scale'],
                                 tuple(data[f'weights_{k}'] for k in range(layers)),
                                 tuple(data[f'biases_{k}'] for k in range(layers)),
                                 str(data['source']), quadratic if quadratic.size else None)
    except FileNotFoundError as exc:
        raise ClassifierError(f'classifier file not found: {path}') from exc
    except (OSError, KeyError, ValueError) as exc:
        raise ClassifierError(f'cannot read classifier file {path}: {exc}') from exc
    sizes = [clf.mean.shape[0]] + [w.shape[1] for w in clf.weights]
    quadratic_shape = (len(clf.classes), sizes[0], sizes[0])
    if clf.feature_set not in (*FEATURE_SETS, *IMAGE_FEATURE_SETS) or \
            sizes[-1] != len(clf.classes) or \
            any(w.shape[0] != n for w, n in zip(clf.weights, sizes, strict=False)) or \
            clf.quadratic is not None and (len(clf.weights) != 1 or
                                           clf.quadratic.shape != quadratic_shape):
        raise ClassifierError(f'{path}: inconsistent classifier (feature set '
                              f'{clf.feature_set!r}, layer sizes {sizes})')
    accepted = (feature_set,) if isinstance(feature_set, str) else feature_set
    if accepted is not None and clf.feature_set not in accepted:
        raise ClassifierError(f'{path} classifies {clf.feature_set!r} features, expected '
                              f'{" or ".join(map(repr, accepted))}')
    return clf
