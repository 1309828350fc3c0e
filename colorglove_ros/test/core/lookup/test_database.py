"""Tests for the pose database: sampling, building, storage and its refusals."""
from __future__ import annotations

import json
import resource
from pathlib import Path

import numpy as np
import pytest
from label_samples import random_blob_images
from repo_paths import CONFIG_DIR
from small_databases import RENDER_CAM, blob_database

from colorglove_ros.core.conventions import TINY_SIZE
from colorglove_ros.core.hand.poses import named_neighbourhood_rows, pose_features
from colorglove_ros.core.lookup.database import (
    DATABASE_VERSION,
    DatabaseError,
    contents_tag,
    load_database,
    map_into_process,
    pixel_keys,
    read_into_page_cache,
    save_database,
    start_reading_into_page_cache,
)
from colorglove_ros.core.lookup.database_build import (
    BuildConfig,
    farthest_point_sampling,
    read_database_config,
    sample_configurations,
)


def _small_db(n: int = 120):
    rng = np.random.default_rng(5)
    tiny = random_blob_images(rng, n, blobs=4)
    poses = rng.normal(size=(n, 26))
    crop = rng.uniform(1, 2, (n, 3))
    return blob_database(tiny, poses, crop, num_bits=32, num_pairs=200, meta={'note': 'test'})


def test_farthest_point_sampling_is_low_dispersion() -> None:
    pts = np.array([[0.0], [1.0], [2.0], [10.0], [2.5], [9.0], [5.0]])
    idx, radius = farthest_point_sampling(pts, 3, seed=0)
    assert len(set(idx.tolist())) == 3
    first = pts[idx[0], 0]
    assert pts[idx[1], 0] == (0.0 if first >= 5.0 else 10.0)   # farthest from the start
    assert radius[-1] == pytest.approx(np.abs(pts - pts[idx].T).min(axis=1).max())
    assert np.all(np.diff(radius) <= 1e-12)          # dispersion never grows
    # brute-force check of the greedy rule on random points
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(200, 5))
    idx, _ = farthest_point_sampling(pts, 20, seed=2)
    for i in range(1, 20):
        d = np.linalg.norm(pts[:, None] - pts[idx[:i]][None], axis=2).min(axis=1)
        assert d[idx[i]] == pytest.approx(d.max(), rel=1e-4)


def test_farthest_point_sampling_continues_from_initial_picks() -> None:
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(300, 4))
    initial = np.array([5, 17, 200])
    idx, radius = farthest_point_sampling(pts, 12, seed=0, initial=initial)
    assert idx[:3].tolist() == initial.tolist() and len(set(idx.tolist())) == 12
    for i in range(3, 12):             # each later pick is the farthest from all before it
        d = np.linalg.norm(pts[:, None] - pts[idx[:i]][None], axis=2).min(axis=1)
        assert d[idx[i]] == pytest.approx(d.max(), rel=1e-4)
    assert radius[-1] == pytest.approx(
        np.linalg.norm(pts[:, None] - pts[idx][None], axis=2).min(axis=1).max(), rel=1e-4)
    for bad in ([1, 1], [300], list(range(13))):
        with pytest.raises(DatabaseError):
            farthest_point_sampling(pts, 12, initial=np.array(bad))


def test_named_shape_configs_cover_the_named_shapes(hand) -> None:
    """The first picks come from the named shapes' neighbourhood and cover it more densely
    than plain farthest-point sampling; none asked for: the plain sampling."""
    model, mesh, _ = hand
    size, count = 400, 40
    rows = named_neighbourhood_rows(size)
    covers = []
    for named in (0, 20):
        cfg = BuildConfig(collection_size=size, fps_vertices=60, named_shape_configs=named)
        coll, chosen, _ = sample_configurations(cfg, count, model, mesh,
                                                np.random.default_rng(cfg.seed))
        assert np.all(chosen[:named] < rows) and len(set(chosen.tolist())) == count
        feats = pose_features(mesh, model, coll, max_vertices=60)
        d = np.linalg.norm(feats[:rows, None] - feats[chosen][None], axis=2).min(axis=1)
        covers.append(float(d.mean()))
    assert covers[1] < 0.8 * covers[0]
    with pytest.raises(DatabaseError):
        sample_configurations(BuildConfig(collection_size=size, named_shape_configs=rows + 1),
                              rows + 1, model, mesh, np.random.default_rng(0))


def test_pinch_shapes_build_setting(hand) -> None:
    """``pinch_shapes`` puts the pinch shapes into the sampled collection (the first named
    picks then cover them) and must be a boolean."""
    from colorglove_ros.core.hand.poses import PINCH_SHAPES

    model, mesh, _ = hand
    cfg = BuildConfig(collection_size=400, fps_vertices=60, named_shape_configs=60,
                      pinch_shapes=True)
    coll, chosen, _ = sample_configurations(cfg, 80, model, mesh, np.random.default_rng(0))
    pinches = np.stack(list(PINCH_SHAPES.values()))
    near = np.abs(coll[chosen][:, None] - pinches[None]).max(axis=2).min(axis=0)
    assert np.all(np.degrees(near) < 25.0)      # every pinch shape has a pick near it
    with pytest.raises(DatabaseError):
        BuildConfig(pinch_shapes=1)


def test_pixel_keys() -> None:
    tiny = np.zeros((2, 40, 40), np.uint8)
    tiny[0, 1, 2] = 3
    tiny[1, 39, 39] = 10
    tiny[1, 0, 0] = 1
    keys, counts = pixel_keys(tiny)
    assert counts.tolist() == [1, 2]
    assert keys[0, 0] == 2 * 1600 + 1 * 40 + 2
    assert keys[0, 1] == 16000                       # padding reads a zero
    assert sorted(keys[1].tolist()) == [0, 9 * 1600 + 1599]


def test_round_trip(tmp_path: Path) -> None:
    db = _small_db()
    save_database(db, tmp_path / 'db')
    loaded = load_database(tmp_path / 'db')
    assert len(loaded) == len(db) and loaded.num_bits == 32
    for name in ('poses', 'tiny', 'dts', 'codes', 'crop', 'pixel_keys', 'patch_xy'):
        np.testing.assert_array_equal(np.asarray(getattr(loaded, name)), getattr(db, name))
    assert isinstance(loaded.tiny, np.memmap)
    np.testing.assert_array_equal(loaded.encoder.dims, db.encoder.dims)
    assert loaded.meta['note'] == 'test' and loaded.render_camera == RENDER_CAM


def test_contents_tag_names_the_poses_and_codes(tmp_path: Path) -> None:
    """Caches computed with a database are named by its contents: the same files give the same
    tag, other poses another one; a manifest without the checksums is refused."""
    first = save_database(_small_db(), tmp_path / 'a')
    other_db = _small_db()
    other_db.poses[0] += 1.0
    other = save_database(other_db, tmp_path / 'b')
    assert contents_tag(first) == contents_tag(first) != contents_tag(other)
    assert contents_tag(first).startswith('db') and len(contents_tag(first)) == 10
    manifest = json.loads((first / 'manifest.json').read_text())
    del manifest['arrays']['codes']
    (first / 'manifest.json').write_text(json.dumps(manifest))
    with pytest.raises(DatabaseError, match='checksums'):
        contents_tag(first)
    with pytest.raises(DatabaseError, match='not found'):
        contents_tag(tmp_path / 'missing')


def test_every_array_file_is_read_into_the_page_cache(tmp_path: Path) -> None:
    """The background reader goes through every array file the manifest lists, start to end
    (chunks smaller than a file included), on a daemon thread."""
    save_database(_small_db(), tmp_path / 'db')
    listed = json.loads((tmp_path / 'db' / 'manifest.json').read_text())['arrays']
    sizes = sum((tmp_path / 'db' / info['file']).stat().st_size for info in listed.values())
    assert read_into_page_cache(tmp_path / 'db', chunk_bytes=1000) == sizes
    thread = start_reading_into_page_cache(tmp_path / 'db')
    assert thread.daemon
    thread.join(10.0)
    assert not thread.is_alive()
    with pytest.raises(DatabaseError, match='not found'):
        read_into_page_cache(tmp_path / 'nothing_here')

def _faults_reading_every_page(db) -> int:
    """This thread's minor page faults while one byte of every page of ``db``'s arrays is
    read through their mappings."""
    before = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
    for name in ('dts', 'pixel_keys', 'tiny', 'codes'):
        np.asarray(getattr(db, name)).reshape(-1).view(np.uint8)[::4096].sum()
    return resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - before


def test_the_arrays_pages_are_mapped_into_the_process(tmp_path: Path) -> None:
    """``map_into_process`` reads every page of the memory-mapped arrays through their
    mappings: afterwards reading them all again takes (almost) no page fault, where a fresh
    load of the same files (their pages in the page cache, just written) takes one per few
    pages; so does the reader thread given the database. Arrays in memory are skipped."""
    save_database(_small_db(1000), tmp_path / 'db')
    fresh = load_database(tmp_path / 'db')
    pages = map_into_process(fresh)
    assert pages >= fresh.dts.nbytes // 4096
    assert _faults_reading_every_page(fresh) <= 2
    unmapped = load_database(tmp_path / 'db')
    assert _faults_reading_every_page(unmapped) >= 5     # (the kernel maps several pages a fault)
    threaded = load_database(tmp_path / 'db')
    thread = start_reading_into_page_cache(tmp_path / 'db', threaded)
    thread.join(10.0)
    assert not thread.is_alive() and _faults_reading_every_page(threaded) <= 2
    assert map_into_process(_small_db(5)) == 0        # in memory: nothing to map


def _corrupt(path: Path, how: str) -> None:
    manifest = path / 'manifest.json'
    if how == 'version':
        data = json.loads(manifest.read_text())
        data['version'] = DATABASE_VERSION + 1
        manifest.write_text(json.dumps(data))
    elif how == 'manifest':
        manifest.write_text('{not json')
    elif how == 'no_manifest':
        manifest.unlink()
    elif how == 'truncated':
        f = path / 'tiny.npy'
        f.write_bytes(f.read_bytes()[:-100])
    elif how == 'flipped':
        f = path / 'codes.npy'
        raw = bytearray(f.read_bytes())
        raw[-5] ^= 0xFF
        f.write_bytes(bytes(raw))
    elif how == 'missing_file':
        (path / 'dts.npy').unlink()


@pytest.mark.parametrize('how', ['version', 'manifest', 'no_manifest', 'truncated', 'flipped',
                                 'missing_file'])
def test_refuses_damaged_database(tmp_path: Path, how: str) -> None:
    save_database(_small_db(40), tmp_path / 'db')
    _corrupt(tmp_path / 'db', how)
    with pytest.raises(DatabaseError):
        load_database(tmp_path / 'db')


def test_refuses_missing_directory(tmp_path: Path) -> None:
    with pytest.raises(DatabaseError, match='not found'):
        load_database(tmp_path / 'nothing_here')


def test_build_small_database_with_renderer(small_database, hand, tmp_path: Path) -> None:
    """The session's small database (``small_databases.SMALL_BUILD``, rendered by
    ``build_database``): entries, renders and patch constraints."""
    from colorglove_ros.core.lookup.search import PoseLookup

    db = small_database
    assert len(db) == 96 and db.meta['num_configs'] >= 6
    assert np.all(db.tiny.max(axis=(1, 2)) >= 1)
    assert db.tiny.shape == (96, TINY_SIZE, TINY_SIZE)
    # the hand's centre sits on the optical axis at the configured distance
    _, mesh, glove = hand
    # constraints: a visible patch has a centroid inside the render (it may fall outside the
    # tiny crop window), a positive area and a vertex of that patch; an invisible one has none
    vis = db.patch_vertex >= 0
    assert vis.sum(axis=1).min() >= 3
    full = db.patch_xy * db.crop[:, None, :1] + db.crop[:, None, 1:]
    assert np.all((full[vis] > -0.5) & (full[vis] < 127.5))
    assert np.all(np.isnan(db.patch_xy[~vis]))
    assert np.all(db.patch_pixels[vis] > 0) and np.all(db.patch_pixels[~vis] == 0)
    for e in range(0, 96, 17):
        for p in np.flatnonzero(vis[e]):
            patch_faces = mesh.faces[glove.face_patch == p]
            assert db.patch_vertex[e, p] in patch_faces
            # the centroid's colour in the tiny image is the patch colour nearby
            x, y = np.rint(db.patch_xy[e, p]).astype(int)
            if 0 <= x < TINY_SIZE and 0 <= y < TINY_SIZE and db.patch_pixels[e, p] >= 6:
                win = db.tiny[e, max(0, y - 3):y + 4, max(0, x - 3):x + 4]
                assert glove.patch_color[p] in win
    save_database(db, tmp_path / 'db')
    loaded = load_database(tmp_path / 'db')
    lookup = PoseLookup(loaded, num_candidates=30, num_blend=5)
    from colorglove_ros.core.camera import PinholeCamera
    rc = loaded.render_camera
    cam = PinholeCamera(rc['width'], rc['height'], rc['fx'], rc['fy'], rc['cx'], rc['cy'])
    res = lookup.lookup(np.asarray(loaded.tiny[10]), loaded.crop[10], cam)
    assert res.distances[0] == 0.0
    same = np.flatnonzero(np.all(loaded.tiny == loaded.tiny[10], axis=(1, 2)))
    assert res.indices[0] in same
    # rendered at the entry's own crop and camera: the translation is recovered
    np.testing.assert_allclose(res.poses[0, :3], loaded.poses[res.indices[0], :3], atol=1e-5)


def test_retrain_codes_in_place(tmp_path: Path) -> None:
    from colorglove_ros.core.lookup.database_build import retrain_codes
    from colorglove_ros.core.lookup.distance import dequantize_dts

    save_database(_small_db(60), tmp_path / 'db')
    retrain_codes(tmp_path / 'db', num_bits=80, num_pairs=120, seed=4)
    db = load_database(tmp_path / 'db')
    assert db.num_bits == 80 and db.codes.shape == (2, 60)
    expected = db.encoder.encode_dts(dequantize_dts(db.dts))
    np.testing.assert_array_equal(np.asarray(db.codes).T, expected)


def test_database_config_reads_and_refuses(tmp_path: Path) -> None:
    config, path, lookup = read_database_config(CONFIG_DIR
                                                / 'database.yaml')
    assert config.entries == 100_000 and path.name == 'database_100k'
    assert lookup['num_candidates'] == 300
    bad = tmp_path / 'database.yaml'
    bad.write_text('database: {build: {entries: 5}}\n')
    with pytest.raises(DatabaseError, match='no database.path'):
        read_database_config(bad)
