"""Motion search by example: DTW (lmm.motion_search.dtw) and the cached index (lmm.motion_search.index)."""
import os

import numpy as np
import pytest

from lmm.data import bvh
from lmm.motion_search import dtw as D
from lmm.motion_search import index as I
from lmm.motion_search import windows as W


# --- DTW -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n,m,window", [(5, 5, None), (6, 9, 2), (9, 6, 1), (12, 12, 3), (7, 15, 4), (3, 8, 1)])
def test_dtw_equals_the_plain_double_loop(n, m, window):
    rng = np.random.default_rng(n * 100 + m)
    q = rng.normal(size=(n, 4))
    cands = rng.normal(size=(5, m, 4))
    got = D.dtw_distances(q, cands, window, backend="numpy")
    want = [D.dtw_reference(q, c, window) for c in cands]
    np.testing.assert_allclose(got, want, rtol=1e-10)


def test_dtw_of_a_sequence_with_itself_and_with_a_repeated_frame_is_zero():
    q = np.random.default_rng(0).normal(size=(10, 3))
    stretched = np.repeat(q, 2, axis=0)           # every frame twice: a warp, not a different motion
    assert D.dtw_distances(q, q[None], None, "numpy")[0] == 0.0
    assert D.dtw_distances(q, stretched[None], None, "numpy")[0] == 0.0
    # a narrow band forbids that warp far from the diagonal: the distance becomes positive
    assert D.dtw_distances(q, stretched[None], 1, "numpy")[0] == 0.0  # the band widens by the length difference
    assert D.dtw_distances(q, q[::-1][None], 1, "numpy")[0] > 0.0


def test_dtaidistance_gives_the_same_numbers():
    pytest.importorskip("dtaidistance")
    if not D.have_dtaidistance():
        pytest.skip("dtaidistance without its C library")
    rng = np.random.default_rng(3)
    for n, m, window in [(8, 11, 2), (11, 8, 3), (16, 16, None)]:
        q, cands = rng.normal(size=(n, 19)), rng.normal(size=(4, m, 19))
        np.testing.assert_allclose(D.dtw_distances(q, cands, window, "dtaidistance"),
                                   D.dtw_distances(q, cands, window, "numpy"), rtol=1e-9)


# --- the index -----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    from lmm import DEFAULT_MANIFEST

    sources = I.sources_from_manifest(DEFAULT_MANIFEST)
    index = I.MotionIndex.build(sources, cache_dir=tmp_path_factory.mktemp("search-cache"))
    anims = [bvh.load(s.path) for s in sources]
    return index, anims


def warped_query(anim, start, n, factor, noise_cm, rng):
    """File frames ``[start, start + n)`` of ``anim``'s key joints played ``factor`` times longer (linear
    interpolation of the positions), with Gaussian noise on every position, as a query."""
    keys = W.match_key_joints(anim.names)
    g = anim.global_positions()
    ref = W.reference_height(g[:, keys["hips"], 1])
    kp = g[start:start + n][:, [keys[k] for k in W.KEY_JOINTS]]
    t = np.linspace(0.0, n - 1, int(round(n * factor)))
    i0 = np.floor(t).astype(int)
    i1 = np.minimum(i0 + 1, n - 1)
    w = (t - i0)[:, None, None]
    kp = (1.0 - w) * kp[i0] + w * kp[i1]
    kp = kp + rng.normal(scale=noise_cm, size=kp.shape)  # LAFAN1 is in cm
    return I.query_from_positions(kp, 1.0 / anim.frame_time, ref)


def _found(matches, take, start, tolerance=15):
    return [i for i, m in enumerate(matches) if m.take == take and abs(m.start_frame - start) <= tolerance]


def test_a_window_time_warped_by_1_2_with_noise_finds_its_source_in_the_top_5(shipped):
    index, anims = shipped
    rng = np.random.default_rng(7)
    for _ in range(12):
        t = int(rng.integers(len(anims)))
        start = int(rng.integers(0, anims[t].n_frames - 40))
        q = warped_query(anims[t], start, W.WINDOW_FRAMES, 1.2, 1.0, rng)
        assert len(q) == 38
        found = _found(index.search(q, top=5), t, start)
        assert found, f"{index.sources[t].label} frame {start}: the warped window is not in the top 5"


def test_dtw_reranking_puts_a_long_query_at_another_speed_first(shipped):
    index, anims = shipped
    rng = np.random.default_rng(11)
    first_with, first_without = 0, 0
    trials = 8
    for _ in range(trials):
        t = int(rng.integers(len(anims)))
        start = int(rng.integers(0, anims[t].n_frames - 200))
        q = warped_query(anims[t], start, 90, 1.25, 0.5, rng)
        first_with += _found(index.search(q, top=5), t, start)[:1] == [0]
        first_without += _found(index.search(q, top=5, rerank=0), t, start)[:1] == [0]
    assert first_with >= trials - 1 and first_with >= first_without


def test_a_range_cut_from_an_indexed_take_finds_itself_first(shipped):
    index, _ = shipped
    s = index.sources[2]
    q = I.query_from_bvh(s.path, (400, 460))
    assert len(q) == 60
    best = index.search(q, top=5)
    assert (best[0].file, best[0].start_frame, best[0].end_frame) == (s.label, 400, 460)
    assert best[0].distance < 1e-6 < best[1].distance
    # results of one file never start within half a window of each other
    for a in best:
        for b in best:
            if a is not b and a.file == b.file:
                assert abs(a.start_frame - b.start_frame) >= W.WINDOW_FRAMES // 2
    # excluding the query's own place gives the next best
    again = index.search(q, top=5, exclude=(2, 400, 460))
    assert all(not (m.take == 2 and m.start < 460 and m.start + m.length > 400) for m in again)


def test_long_queries_are_cut_into_overlapping_windows():
    frames = np.zeros((200, W.FRAME_DIM), np.float32)
    win, offsets = I.query_windows(frames)
    assert win.shape == (I.MAX_QUERY_WINDOWS, W.WINDOW_FRAMES, W.FRAME_DIM)
    assert offsets[0] == 0 and offsets[-1] == 200 - W.WINDOW_FRAMES
    win, offsets = I.query_windows(frames[:20])             # short: stretched to one window
    assert win.shape == (1, W.WINDOW_FRAMES, W.FRAME_DIM) and offsets.tolist() == [0]
    with pytest.raises(I.SearchError, match="at least 8"):
        I.query_windows(I._check_query(frames[:5], "q.bvh"))


# --- the cache -----------------------------------------------------------------------------------------

def _small_folder(root, frames=(0, 200)):
    from lmm import DEFAULT_MANIFEST
    from lmm.data.manifest import load_manifest

    clips = load_manifest(DEFAULT_MANIFEST).clips
    (root / "sub").mkdir(parents=True, exist_ok=True)
    bvh.save(root / "a.bvh", bvh.load(clips[0].file).slice(*frames))
    bvh.save(root / "sub" / "b.bvh", bvh.load(clips[1].file).slice(*frames))
    return root


def test_cache_is_reused_and_invalidated_when_a_file_changes(tmp_path):
    folder = _small_folder(tmp_path / "takes")
    cache = tmp_path / "cache"
    sources = I.sources_from(folder)
    assert [s.label for s in sources] == ["a.bvh", "sub/b.bvh"]
    first = I.MotionIndex.build(sources, cache_dir=cache)
    assert not first.from_cache and first.n_windows == 2 * (200 - W.WINDOW_FRAMES + 1)
    again = I.MotionIndex.build(sources, cache_dir=cache)
    assert again.from_cache
    np.testing.assert_array_equal(again.embeddings, first.embeddings)
    np.testing.assert_array_equal(again.frames, first.frames)
    # the same bytes with a new modification time: rebuilt
    st = os.stat(folder / "a.bvh")
    os.utime(folder / "a.bvh", ns=(st.st_atime_ns, st.st_mtime_ns + 5_000_000_000))
    assert not I.MotionIndex.build(sources, cache_dir=cache).from_cache
    # other contents: rebuilt, and the index reflects them
    _small_folder(tmp_path / "takes", frames=(0, 150))
    changed = I.MotionIndex.build(sources, cache_dir=cache)
    assert not changed.from_cache and changed.n_windows == 2 * (150 - W.WINDOW_FRAMES + 1)
    # another embedder: another cache file
    from lmm.motion_search.embed import FeatureEmbedder
    other = I.MotionIndex.build(sources, embedder=FeatureEmbedder(step=2), cache_dir=cache)
    assert not other.from_cache and other.embeddings.shape[1] == 16 * W.FRAME_DIM


def test_a_damaged_cache_file_is_rebuilt(tmp_path):
    sources = I.sources_from(_small_folder(tmp_path / "takes"))
    built = I.MotionIndex.build(sources, cache_dir=tmp_path / "cache")
    built.cache_path.write_bytes(b"not an npz")
    again = I.MotionIndex.build(sources, cache_dir=tmp_path / "cache")
    assert not again.from_cache and again.n_windows == built.n_windows
    assert I.MotionIndex.build(sources, cache_dir=tmp_path / "cache").from_cache


def test_bad_sources_are_one_line_errors_naming_the_file(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(I.SearchError, match=r"empty: the folder holds no \.bvh files"):
        I.sources_from(tmp_path / "empty")
    with pytest.raises(I.SearchError, match="nowhere: no such manifest or folder"):
        I.sources_from(tmp_path / "nowhere")
    folder = _small_folder(tmp_path / "takes")
    anim = bvh.load(folder / "a.bvh")
    anim.names = [n.replace("Hand", "Paw") for n in anim.names]
    bvh.save(folder / "robot.bvh", anim)
    with pytest.raises(W.SkeletonMatchError, match=r"robot\.bvh: cannot match the key joints left_hand, right_hand"):
        I.MotionIndex.build(I.sources_from(folder), cache_dir=tmp_path / "cache")


def test_a_range_of_an_indexed_take_is_cut_from_the_index_exactly_as_read_from_the_file(shipped):
    index, _ = shipped
    s = index.sources[1]
    assert index.source_of(s.path) == 1 and index.source_of("elsewhere.bvh") is None
    np.testing.assert_array_equal(index.query_range(1, (250, 330)), I.query_from_bvh(s.path, (250, 330)))
    with pytest.raises(I.SearchError, match="go past the end"):
        index.query_range(1, (0, int(index.n_file_frames[1]) + 1))


def test_queries_from_a_manifest_range_and_from_a_skeletons_history_equal_the_file_range(shipped):
    from lmm import DEFAULT_MANIFEST
    from lmm.data.manifest import load_manifest

    index, anims = shipped
    manifest = load_manifest(DEFAULT_MANIFEST)
    clip = next(k for k, c in enumerate(manifest.clips) if c.ranges)
    a, b = manifest.clips[clip].ranges[0]
    t = index.source_of(manifest.clips[clip].file)
    np.testing.assert_array_equal(I.query_from_manifest_range(manifest, clip, 0), index.query_range(t, (a, b)))
    # the studio's history: every joint of the skeleton, names matched, the character's own size
    anim = anims[t]
    g = anim.global_positions()
    keys = W.match_key_joints(anim.names)
    ref = W.reference_height(g[:, keys["hips"], 1])
    q = I.query_from_skeleton(anim.names, g[a:b] * 0.01, 1.0 / anim.frame_time, ref * 0.01)
    assert q.shape == (b - a, W.FRAME_DIM)
    best = index.search(q, top=1)[0]
    assert (best.take, abs(best.start_frame - a) <= 2) == (t, True)
    with pytest.raises(W.SkeletonMatchError, match="the character: cannot match the key joints head"):
        I.query_from_skeleton([n.replace("Head", "Top") for n in anim.names], g[a:b], 30.0)


class _StubEncoder:
    name = "stub-encoder"

    def __init__(self):
        self.weights = np.arange(6, dtype=np.float32)

    def embed(self, windows):
        w = np.asarray(windows, np.float32)
        return np.ascontiguousarray(w.mean(axis=1)[:, :6] * self.weights)


def test_the_shipped_encoder_is_the_default_embedder_when_its_weights_exist(tmp_path, monkeypatch):
    import sys
    import types

    sources = I.sources_from(_small_folder(tmp_path / "takes"))
    monkeypatch.setattr(I, "default_encoder_path", lambda: tmp_path / "absent.npz")
    plain = I.MotionIndex.build(sources, cache_dir=tmp_path / "cache")
    assert plain.embedder.name == "features"
    weights = tmp_path / "search_encoder.npz"
    weights.write_bytes(b"stub")
    module = types.ModuleType("lmm.motion_search.encoder")
    module.load_default = _StubEncoder
    monkeypatch.setitem(sys.modules, "lmm.motion_search.encoder", module)
    monkeypatch.setattr(I, "default_encoder_path", lambda: weights)
    learned = I.MotionIndex.build(sources, cache_dir=tmp_path / "cache")
    assert learned.embedder.name == "stub-encoder" and not learned.from_cache
    assert learned.embeddings.shape == (plain.n_windows, 6)
    assert I.MotionIndex.build(sources, cache_dir=tmp_path / "cache").from_cache
    # other weights: another cache entry
    changed = _StubEncoder()
    changed.weights = changed.weights + 1.0
    module.load_default = lambda: changed
    assert not I.MotionIndex.build(sources, cache_dir=tmp_path / "cache").from_cache


def test_a_match_as_a_ghost_starts_at_the_origin_facing_forward_at_the_characters_size(shipped):
    from lmm.motion_search.ghost import segment_positions

    index, anims = shipped
    anim = anims[0]
    keys = W.match_key_joints(anim.names)
    g = anim.global_positions()
    hips_ref = W.reference_height(g[:, keys["hips"], 1])
    # a stretch where the take moves: the one with the largest hips travel over 60 frames
    travel = np.linalg.norm(g[60:, keys["hips"], [0, 2]] - g[:-60, keys["hips"], [0, 2]], axis=1)
    a = int(np.argmax(travel))
    p = segment_positions(anim, a, a + 60, hips_height=0.9)
    assert p.shape == (60, len(anim.names), 3)
    np.testing.assert_allclose(p[0, keys["hips"], [0, 2]], 0.0, atol=1e-5)
    np.testing.assert_allclose(p[0, keys["hips"], 1], g[a, keys["hips"], 1] * 0.9 / hips_ref, rtol=1e-5)
    # facing +Z: the left hand and foot (mean over the first frames) are on +X, the right ones on -X
    k = [keys[j] for j in ("left_hand", "right_hand", "left_foot", "right_foot")]
    across = ((p[:5, k[0]] - p[:5, k[1]]) + (p[:5, k[2]] - p[:5, k[3]])).mean(axis=0)
    assert across[0] > 0.1 and abs(across[2]) < 1e-4 * across[0] + 1e-5, across
    # the shape is the take's, only moved, turned and scaled
    d_take = np.linalg.norm(g[a + 10, keys["head"]] - g[a + 10, keys["left_foot"]]) * 0.9 / hips_ref
    assert abs(np.linalg.norm(p[10, keys["head"]] - p[10, keys["left_foot"]]) - d_take) < 1e-4
