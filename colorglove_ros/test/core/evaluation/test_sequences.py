"""Tests of the evaluation pipeline (core/evaluation/sequences.py) and the eval_ik /
learn_ik_covariances
commands, on the session's small rendered database (conftest.py)."""
from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.core.camera import load_calibration
from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.metrics import fingertip_errors_mm, jitter_mm
from colorglove_ros.core.evaluation.sequences import (
    EvaluationError,
    SequenceEvaluator,
    contiguous_runs,
    eval_seeds,
    find_database,
    jitter_runs_mm,
    make_observer,
    observe_camera,
    summarize,
    train_seeds,
    training_sequences,
)
from colorglove_ros.core.lookup.search import PoseLookup
from colorglove_ros.core.lookup.temporal_prior import reweight_by_previous
from colorglove_ros.core.pipeline import UNGATED, FrameObservations, FramePipeline, TemporalPrior
from colorglove_ros.core.synthetic.frames import Synthesizer, render_frame
from colorglove_ros.core.synthetic.sequences import generate_sequence
from colorglove_ros.core.tracking.config import IKConfig, load_covariances
from colorglove_ros.core.tracking.tracker import HandTracker
from colorglove_ros.tools import eval_ik, learn_ik_covariances


@pytest.fixture(scope='module')
def rigs():
    root = CONFIG_DIR
    return (load_calibration(root / 'calibration.yaml'),
            load_calibration(root / 'calibration_stereo.yaml'))


@pytest.fixture(scope='module')
def synth():
    s = Synthesizer()
    yield s
    s.release()


def test_seed_sets_are_disjoint():
    assert not set(eval_seeds(50)) & set(train_seeds(50))
    with pytest.raises(EvaluationError):
        eval_seeds(0)


def test_tuning_seeds_are_offset_from_the_reported_ones():
    assert eval_seeds(2, 1000) == [1000, 1001]
    assert not set(eval_seeds(2, 1000)) & set(eval_seeds(4))
    assert not set(eval_seeds(2, 1000)) & set(train_seeds(50))
    with pytest.raises(EvaluationError):
        eval_seeds(2, -1)


def test_contiguous_runs_and_jitter(synth):
    assert contiguous_runs(np.array([1, 1, 0, 1, 0, 0, 1, 1, 1], bool)) == [(0, 2), (3, 4),
                                                                           (6, 9)]
    Q = generate_sequence(5, 30, model=synth.model)
    full = np.ones(30, bool)
    assert jitter_runs_mm(synth.model, Q, full) == pytest.approx(jitter_mm(synth.model, Q))
    gap = full.copy()
    gap[12] = False               # two runs: 0..11 and 13..29, weighted by frames
    a, b = jitter_mm(synth.model, Q[:12]), jitter_mm(synth.model, Q[13:])
    assert jitter_runs_mm(synth.model, Q, gap) == pytest.approx((a * 8 + b * 13) / 21)
    assert math.isnan(jitter_runs_mm(synth.model, Q, np.zeros(30, bool)))


def test_find_database_picks_the_largest(tmp_path):
    for name, n in (('small', 10), ('big', 500), ('other', 50)):
        (tmp_path / name).mkdir()
        (tmp_path / name / 'manifest.json').write_text(json.dumps(
            {'format': 'colorglove_pose_database', 'num_entries': n}))
    (tmp_path / 'junk').mkdir()
    assert find_database(tmp_path) == tmp_path / 'big'
    assert find_database(tmp_path / 'junk') is None


def test_rigs_must_share_the_primary_camera(small_database_path, rigs, synth):
    from colorglove_ros.core.lookup.database import load_database

    mono, stereo = rigs
    lookup = PoseLookup(load_database(small_database_path))
    with pytest.raises(EvaluationError):
        SequenceEvaluator(lookup, {'a': stereo.cameras[1:], 'b': stereo.cameras},
                          synthesizer=synth)


def test_pipeline_end_to_end_finite(small_database_path, rigs, synth):
    from colorglove_ros.core.lookup.database import load_database

    mono, stereo = rigs
    ev = SequenceEvaluator(PoseLookup(load_database(small_database_path)),
                           {'1': mono.cameras, '2': stereo.cameras}, synthesizer=synth,
                           keep_results=True)
    out = ev.run(eval_seeds(1)[0], 8)
    assert set(out) == {(r, m) for r in ('1', '2') for m in ('blend', 'ik', 'ik_smooth')}
    for (rig, _mode), run in out.items():
        assert run.found.sum() >= 6        # the generated hand stays inside the image
        s = summarize(ev.model, [run])
        for key in ('joint_mae_deg', 'fingertip_mm', 'wrist_plane_mm', 'wrist_depth_mm',
                    'reprojection_px', 'jitter_mm', 'ik_ms_mean', 'ik_ms_p95'):
            assert math.isfinite(s[key]), key
        assert s['fingertip_mm'] > 0
        if rig == '2':
            assert np.any(np.array([r.constraints_per_camera[1] for r in run.results
                                    if r is not None and r.found]) > 0)
    # every (rig, mode) saw the same lookup: identical blends
    b1, b2 = out[('1', 'blend')], out[('2', 'ik')]
    same = b1.found & b2.found
    qb1 = np.array([r.q_blend for r, f in zip(b1.results, same, strict=True) if f])
    qb2 = np.array([r.q_blend for r, f in zip(b2.results, same, strict=True) if f])
    assert np.allclose(qb1[:, 6:], qb2[:, 6:])
    seqs = training_sequences(out[('1', 'ik')])
    assert sum(len(s) for s in seqs) == int(out[('1', 'ik')].found.sum())


def test_temporal_prior_reweights_by_each_trackers_previous_output(small_database_path, rigs, synth,
                                                                   monkeypatch):
    from colorglove_ros.core.lookup import temporal_prior
    from colorglove_ros.core.lookup.database import load_database

    calls = []

    def spy(result, q_prev, tau_rad, rotation_weight):
        out = reweight_by_previous(result, q_prev, tau_rad, rotation_weight)
        calls.append((None if q_prev is None else q_prev.copy(), tau_rad, rotation_weight,
                      out.blended))
        return out

    monkeypatch.setattr(temporal_prior, 'reweight_by_previous', spy)
    mono, _ = rigs
    ev = SequenceEvaluator(PoseLookup(load_database(small_database_path), num_blend=5),
                           {'1': mono.cameras}, modes=('blend',), synthesizer=synth,
                           keep_results=True, temporal=TemporalPrior(0.3, 0.5),
                           finger_evidence=False)
    run = ev.run(eval_seeds(1)[0], 6)[('1', 'blend')]
    assert run.found.all() and len(calls) == 6
    assert calls[0][0] is None                      # first frame: no previous output
    for i in range(1, 6):
        q_prev, tau, weight, blended = calls[i]
        np.testing.assert_allclose(q_prev, run.q_est[i - 1])
        assert (tau, weight) == (0.3, 0.5)
        # the tracker's prior is the reweighted blend
        np.testing.assert_allclose(run.results[i].q_blend[6:], blended[6:], atol=1e-9)


def test_eval_ik_cli_temporal_option(small_database_path, tmp_path, capsys):
    out = tmp_path / 'eval.json'
    args = ['--database', str(small_database_path), '--frames', '4', '--sequences', '1', '--modes',
            'blend', '--plot', '']
    assert eval_ik.main([*args, '--temporal-tau', '30', '--num-blend', '12',
                         '--temporal-rotation-weight', '0', '--no-finger-evidence',
                         '--json', str(out)]) == 0
    settings = json.loads(out.read_text())['settings']
    assert (settings['temporal_tau_deg'], settings['temporal_rotation_weight'],
            settings['num_blend']) == (30.0, 0.0, 12)
    assert 'temporal tau: 30 deg' in capsys.readouterr().out
    assert eval_ik.main([*args, '--temporal-tau', '0']) == 1
    assert '--temporal-tau must be > 0' in capsys.readouterr().err
    # the temporal reweighting re-blends every DOF: refused with the per-finger blend
    assert eval_ik.main([*args, '--temporal-tau', '30']) == 1
    assert 'without the per-finger blend' in capsys.readouterr().err


class _OracleLookup:
    """Ground-truth neighbour: the true pose perturbed as a blend, constraints measured on
    the true rendering (patch centroids mapped into the tiny image, nearest patch vertex)."""

    def __init__(self, synth: Synthesizer, rng: np.random.Generator) -> None:
        self.synth, self.rng = synth, rng
        self.truth: np.ndarray | None = None
        self.frame = None
        faces = synth.mesh.faces
        self.patch_vertices = [np.unique(faces[synth.glove.face_patch == p])
                               for p in range(len(synth.glove.patch_color))]

    def lookup(self, tiny, crop, camera, blobs=None):
        q = self.truth
        verts = self.synth.mesh.skin(self.synth.model, q)
        ids = self.frame.patch_ids
        pids, xy, vs, counts = [], [], [], []
        for p, pv in enumerate(self.patch_vertices):
            ys, xs = np.nonzero(ids == p + 1)
            if len(xs) < 30:
                continue
            c = np.array([xs.mean(), ys.mean()])
            proj = camera.project(verts[pv])
            v = pv[int(np.argmin(np.linalg.norm(proj - c, axis=1)))]
            pids.append(p)
            xy.append(crop.to_tiny(c))
            vs.append(v)
            counts.append(len(xs) / crop.scale**2)
        blended = q.copy()
        blended[0:3] += self.rng.normal(0, [0.01, 0.01, 0.03])
        blended[3:6] += self.rng.normal(0, 0.04, 3)
        blended[6:] += self.rng.normal(0, 0.15, 20)
        cons = SimpleNamespace(patch_ids=np.array(pids), colors=self.synth.glove.patch_color[pids],
                               vertices=np.array(vs), tiny_xy=np.array(xy),
                               pixel_counts=np.array(counts))
        return SimpleNamespace(blended=self.synth.model.clamp(blended), constraints=cons)


def test_ik_lowers_fingertip_error_on_ground_truth_neighbours(rigs, synth):
    mono, _ = rigs
    cam = mono.cameras[0]
    oracle = _OracleLookup(synth, np.random.default_rng(0))
    pipeline = FramePipeline(lambda frame, primary: observe_camera(frame.labels, primary),
                             oracle, cam, limits=UNGATED, finger_evidence=False)
    err = {'blend': [], 'ik': []}
    for seed in (3, 4, 5):
        # the oracle's constraint vertices are the ones nearest the true patch centroids, the
        # 'vertex' constraint model's assumption
        cfg = IKConfig(constraint_model='vertex')
        trackers = {m: HandTracker(synth.model, synth.mesh, [cam], cfg.with_mode(m))
                    for m in err}
        Q = generate_sequence(seed, 8, camera=cam, model=synth.model)
        for i, q in enumerate(Q):
            frame = render_frame(q, cam, np.random.default_rng(i), synthesizer=synth)
            oracle.truth, oracle.frame = q, frame
            obs, tiny = observe_camera(frame.labels, True)
            prior = pipeline.look_up(FrameObservations((obs,), tiny))
            assert prior.result is not None
            for m, tr in trackers.items():
                r = tr.update(prior.result, [obs], i / 30)
                assert r.found
                err[m].append(fingertip_errors_mm(synth.model, r.q[None], q[None])[0])
    # median over 24 frames: a single-camera IK can settle in a wrong but well-reprojecting
    # pose on an occasional frame
    e_blend, e_ik = np.median(err['blend']), np.median(err['ik'])
    assert e_blend > 10.0
    assert e_ik < 0.75 * e_blend


def test_eval_ik_cli_writes_documented_json(small_database_path, tmp_path, capsys):
    out = tmp_path / 'eval.json'
    png = tmp_path / 'eval.png'
    rc = eval_ik.main(['--database', str(small_database_path), '--frames', '6', '--sequences', '1',
                       '--json', str(out), '--plot', str(png)])
    assert rc == 0
    data = json.loads(out.read_text())
    assert tuple(data) == eval_ik.JSON_KEYS
    assert len(data['rows']) == 6
    for row in data['rows']:
        for key in ('cameras', 'mode', 'joint_mae_deg', 'fingertip_mm', 'wrist_plane_mm',
                    'wrist_depth_mm', 'reprojection_px', 'jitter_mm', 'ik_ms_mean',
                    'ik_ms_p95', 'fingertip_rel_wrist_mm', 'fingertip_hand_frame_mm',
                    'fingertip_rotation_only_mm'):
            assert key in row
        assert math.isfinite(row['fingertip_mm'])
        assert math.isfinite(row['fingertip_hand_frame_mm'])
    assert {t['result'] for t in data['targets']} <= {'PASS', 'FAIL'}
    assert any('depth error < 10 mm' in t['target'] for t in data['targets'])
    fingertip = [t['target'] for t in data['targets']
                 if 'fingertip 3-D error < 15 mm' in t['target']]
    assert fingertip == ['1 camera: fingertip 3-D error < 15 mm (mean), relative to the wrist '
                         'position']
    smooth_row = next(r for r in data['rows']
                      if r['cameras'] == '1 camera' and r['mode_key'] == 'ik_smooth')
    assert data['reference'] == [{
        'figure': '1 camera: fingertip 3-D error (mean), absolute: includes the wrist '
                  'translation error',
        'measured': smooth_row['fingertip_mm']}]
    assert data['settings']['seeds'] == [0]
    assert png.stat().st_size > 1000
    assert 'Targets' in capsys.readouterr().out


def test_eval_ik_cli_refuses_a_database_without_its_hand_length(tmp_path, capsys, monkeypatch):
    db = SimpleNamespace(meta={'build': {'glove_seed': 0}})
    from colorglove_ros.core.evaluation import sequences

    monkeypatch.setattr(sequences, 'open_database', lambda path, root: (tmp_path, db))
    assert eval_ik.main(['--plot', '']) == 1
    assert 'hand length' in capsys.readouterr().err


def test_eval_ik_cli_reports_missing_database(tmp_path, capsys):
    assert eval_ik.main(['--database', str(tmp_path / 'none'), '--plot', '']) == 1
    assert 'not found' in capsys.readouterr().err


def test_learn_covariances_cli_saves_a_loadable_file(small_database_path, tmp_path):
    out = tmp_path / 'cov.yaml'
    js = tmp_path / 'cov.json'
    rc = learn_ik_covariances.main(['--database', str(small_database_path), '--frames', '10',
                                    '--sequences', '1', '--output', str(out), '--json', str(js)])
    assert rc == 0
    cov = load_covariances(out)
    assert cov.q_var.shape == (26,) and np.all(cov.q_var > 0) and np.all(cov.p_var > 0)
    data = json.loads(js.read_text())
    assert set(data) >= {'output', 'provenance', 'r_std_px', 'dofs', 'summary'}
    assert data['provenance']['train_seeds'].startswith(str(train_seeds(1)[0]))
    assert len(data['dofs']) == 26
    assert data['r_std_px'][0] == pytest.approx(math.sqrt(cov.r_var_px2[0]))


def test_segmenter_observer_converts_blobs_and_crop():
    from colorglove_ros.core.evaluation.sequences import segmenter_observer
    from colorglove_ros.core.segmentation.crop import CropTransform
    from colorglove_ros.core.segmentation.types import Blob, Observation

    crop = CropTransform(2.0, 10.0, 20.0)
    seen = Observation(True, 'ok', 640, 480, np.ones((40, 40), np.uint8), crop,
                       [Blob(3, 100.5, 50.0, 40), Blob(7, 120.0, 60.0, 12)])

    class _Seg:
        def process(self, image, keep_labels=False):
            assert image.shape == (480, 640, 3) and not keep_labels
            return seen

    frame = SimpleNamespace(image_rgb=np.zeros((480, 640, 3), np.uint8))
    obs, tiny = segmenter_observer(_Seg())(frame, True)
    assert obs.hand_found and obs.crop is crop and tiny.transform is crop
    assert obs.blobs.color.tolist() == [3, 7]
    assert np.allclose(obs.blobs.centroid_px, [[100.5, 50.0], [120.0, 60.0]])
    obs2, tiny2 = segmenter_observer(_Seg())(frame, False)
    assert obs2.hand_found and tiny2 is None
    seen.hand_found = False
    obs3, tiny3 = segmenter_observer(_Seg())(frame, True)
    assert not obs3.hand_found and tiny3 is None


def test_the_trackers_evidence_is_recorded_per_tracked_frame(small_database_path, rigs, synth):
    """With ``evidence`` every tracked frame carries the lookup's nearest image distance, the
    explained blob share, the reprojection error, the constraint count and the missing-glove
    share; without it nothing is recorded."""
    from colorglove_ros.core.evaluation.sequences import EVIDENCE_FIELDS
    from colorglove_ros.core.lookup.database import load_database

    mono, _ = rigs
    lookup = PoseLookup(load_database(small_database_path))
    run = SequenceEvaluator(lookup, {'1': mono.cameras}, modes=('ik_smooth',),
                            synthesizer=synth, evidence=True).run(eval_seeds(1)[0], 4)
    run = run[('1', 'ik_smooth')]
    assert run.found.sum() >= 3 and set(run.evidence) == set(EVIDENCE_FIELDS)
    for key in ('image_distance', 'explained_blob_share', 'constraints'):
        values = run.evidence[key]
        assert np.all(np.isfinite(values[run.found])) and np.all(np.isnan(values[~run.found]))
    np.testing.assert_array_equal(run.evidence['constraints'][run.found],
                                  run.constraints[run.found])
    assert np.all(run.evidence['image_distance'][run.found] >= 0.0)
    plain = SequenceEvaluator(lookup, {'1': mono.cameras}, modes=('ik_smooth',),
                              synthesizer=synth).run(eval_seeds(1)[0], 2)
    assert plain[('1', 'ik_smooth')].evidence == {}


def _copying_fit(source, calls):
    """A stand-in for ``calibrate_synthetic`` that saves the ready-made calibration
    ``source`` at the output it is asked for and records the call."""
    import shutil

    def fit(count, output, frames_out, **options):
        calls.append(count)
        shutil.copyfile(source, output)
        return SimpleNamespace(output=output, fit_s=0.0)

    return fit


def test_segmented_observer_fits_the_missing_default_calibration_once(node_assets, tmp_path,
                                                                      monkeypatch, capsys):
    """An evaluation run before the demo on a new machine: the package's colour config names
    a calibration file that does not exist yet; the segmented observer fits it (once), as the
    demo does, instead of failing on the missing file."""
    from colorglove_ros.core.segmentation import calibration_fit

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv('COLORGLOVE_DATA_DIR', str(tmp_path / 'data'))
    (tmp_path / 'data').mkdir()
    calls: list[int] = []
    monkeypatch.setattr(calibration_fit, 'calibrate_synthetic',
                        _copying_fit(node_assets.calibration_npz, calls))
    observe = make_observer('segmented')
    assert calls == [calibration_fit.FIRST_USE_FRAMES]
    assert (tmp_path / 'data' / 'color_calibration.npz').is_file()
    assert 'no colour calibration at' in capsys.readouterr().out
    assert callable(observe)
    make_observer('segmented')
    assert calls == [calibration_fit.FIRST_USE_FRAMES]        # the second time it is there


def test_segmented_observer_does_not_fit_a_calibration_the_user_named(tmp_path, monkeypatch):
    """A colour config the user gives whose calibration file is missing is their error: no
    synthetic calibration is made behind their back."""
    from colorglove_ros.core.segmentation import calibration_fit

    lines = (CONFIG_DIR / 'color_calibration.yaml').read_text().splitlines()
    missing = tmp_path / 'mine.npz'
    config = tmp_path / 'mine.yaml'
    config.write_text('\n'.join(f'calibration_file: {missing}' if line.startswith(
        'calibration_file:') else line for line in lines) + '\n')
    calls: list[int] = []
    monkeypatch.setattr(calibration_fit, 'calibrate_synthetic',
                        _copying_fit(tmp_path / 'unused.npz', calls))
    with pytest.raises(ColorGloveError, match='mine.npz'):
        make_observer('segmented', config)
    assert calls == [] and not missing.exists()


def test_the_observation_record_keeps_the_tiny_image_and_the_largest_blobs_in_its_frame():
    """record_observation writes a frame's tiny label image and its blobs, largest first, in
    the tiny image's pixel frame with their pixel counts in tiny pixels; a frame without a
    crop stays empty; more blobs than the record holds keeps the largest."""
    from colorglove_ros.core.evaluation.sequences import record_observation
    from colorglove_ros.core.hand.observation_features import (
        MAX_RECORDED_BLOBS,
        empty_observation_record,
        frame_features,
        record_features,
    )
    from colorglove_ros.core.segmentation.crop import CropTransform, TinyCrop
    from colorglove_ros.core.tracking.types import Blobs, CameraObservation

    record = empty_observation_record(2)
    tiny = np.zeros((40, 40), np.uint8)
    tiny[10:20, 5:9] = 3
    transform = CropTransform(2.0, 100.0, 50.0)
    n = MAX_RECORDED_BLOBS + 3
    blobs = Blobs(np.arange(n) % 10 + 1, np.stack([100.0 + 2.0 * np.arange(n),
                                                   np.full(n, 60.0)], axis=1),
                  np.arange(n, dtype=float) + 1.0)
    seen = FrameObservations((CameraObservation(True, blobs, transform),),
                             TinyCrop(tiny, transform))
    record_observation(record, 1, seen)
    record_observation(record, 0, FrameObservations(seen.cameras, None))
    assert not record['tiny_labels'][0].any() and not record['blob_color'][0].any()
    np.testing.assert_array_equal(record['tiny_labels'][1], tiny)
    largest = n - 1
    assert record['blob_color'][1, 0] == largest % 10 + 1
    np.testing.assert_allclose(record['blob_tiny_xy'][1, 0], [largest, 5.0])
    assert record['blob_tiny_pixels'][1, 0] == pytest.approx((largest + 1.0) / 4.0)
    assert (record['blob_color'][1] > 0).sum() == MAX_RECORDED_BLOBS
    assert record['blob_tiny_pixels'][1].min() == pytest.approx(4.0 / 4.0)
    # the spelling node's features of one frame are the record's
    np.testing.assert_array_equal(frame_features(tiny, transform, blobs),
                                  record_features(record)[1])
