"""``pmj02bn`` (issue 20, item 1): the point sets' (0,2) property at every power-of-two
prefix (shipped and freshly generated; a generator without the elementary-interval check
fails it), the stream's draws (shifted pmj02bn prefixes, stratified 1D draws, the pixel
tile), uniformity over seeds and the sample-count limit. Pass splitting, unbiasedness,
freezing and XML round trips are tested with the other samplers in test_samplers.py."""

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from pbr.samplers import pmj02bn as pmj
from test_samplers import CHI2_999, chi2_uniform, draws, is_net, make


def test_every_power_of_two_prefix_of_the_shipped_sets_is_a_0_2_net():
    sets = pmj.pmj02bn_sets()
    assert sets.shape == (pmj.N_SETS, pmj.N_POINTS, 2) and sets.dtype == np.uint32
    pts = sets / 2.0 ** 32
    for s in range(pmj.N_SETS):
        for k in range(13):      # 1, 2, 4, ..., 4096 points: all shapes of area 2^-k
            assert is_net(pts[s, :1 << k], k), (s, k)
    # the sets differ (independent realisations)
    assert not np.array_equal(sets[0], sets[1])


def test_the_generator_makes_0_2_sequences_and_fails_without_its_check():
    rng = np.random.default_rng(7)
    pts = pmj.generate_pmj02bn(256, rng)
    assert all(is_net(pts[:1 << k], k) for k in range(9))
    # multi-jittered by cell only (no elementary-interval check): not (0,2)
    bad = pmj.generate_pmj02bn(256, np.random.default_rng(7), check=False)
    assert not all(is_net(bad[:1 << k], k) for k in range(9))


def test_blue_noise_placement_spreads_the_points():
    """Best-candidate placement: the smallest distance between points is larger than
    with one random valid candidate (the plain pmj02)."""
    def min_dist(p):
        d = np.abs(p[:, None] - p[None])
        d = np.minimum(d, 1 - d)
        d = np.sqrt((d ** 2).sum(-1)) + np.eye(len(p))
        return d.min()
    bn = pmj.generate_pmj02bn(256, np.random.default_rng(3))
    plain = pmj.generate_pmj02bn(256, np.random.default_rng(3), candidates=1)
    assert min_dist(bn) > 1.3 * min_dist(plain)


@pytest.mark.parametrize("spp", [16, 64, 32])
def test_2d_draws_are_shifted_pmj02bn_prefixes_and_1d_draws_are_stratified(spp):
    """In each pixel: the 2D draws are a toroidal shift (per pixel and dimension) of a
    permutation of a set's first spp points, a (0,2)-net (set d / 2 mod 5 for dimension
    d); 1D draws have one sample per 1/spp stratum."""
    d = draws("pmj02bn", spp, size=(3, 2), pattern="121212121212")
    table = pmj.pmj02bn_sets() / 2.0 ** 32
    shifts = []
    for pixel in d:
        col = 0
        dim = 2
        for c in "121212121212":
            if c == "1":
                assert sorted(np.floor(pixel[:, col] * spp).astype(int)) == list(range(spp))
                col, dim = col + 1, dim + 1
                continue
            pts = table[(dim // 2) % pmj.N_SETS, :spp]
            # a permutation of the prefix, shifted: one shift maps every draw to a point
            shift = np.mod(pixel[:, col:col + 2][:, None] - pts[None], 1.0)     # [draw, point]

            def fits(delta):
                d = np.abs(shift - delta)
                return (np.minimum(d, 1 - d) < 1e-5).all(-1).sum(1) == 1

            found = [shift[0, j] for j in range(spp) if fits(shift[0, j]).all()]
            assert len(found) == 1
            d = np.abs(shift - found[0])
            matched = (np.minimum(d, 1 - d) < 1e-5).all(-1).argmax(1)
            assert sorted(matched) == list(range(spp))      # each point drawn once
            shifts.append(found[0])
            assert is_net(pts, spp.bit_length() - 1)
            col, dim = col + 2, dim + 2
    # the shifts differ between pixels and dimensions
    assert len(np.unique(np.round(np.array(shifts), 4), axis=0)) == len(shifts)


@pytest.mark.parametrize("spp", [1, 16, 64])
def test_the_pixel_tile_holds_set_0_sorted_into_pixels(spp):
    """pixel_2d's table: pixel (x, y) of the tile holds set 0's points inside its
    sub-square (scaled to the pixel): all 4096 points once, for a power of 4."""
    tile, t = pmj.pixel_tile(spp)
    assert tile * tile * spp == pmj.N_POINTS
    t = t.reshape(tile, tile, spp, 2).astype(np.float64) / 2.0 ** 32     # [y, x]
    y, x = np.meshgrid(np.arange(tile), np.arange(tile), indexing="ij")
    full = np.stack([(x[..., None] + t[..., 0]) / tile, (y[..., None] + t[..., 1]) / tile], -1).reshape(-1, 2)
    ref = pmj.pmj02bn_sets()[0] / 2.0 ** 32
    key = lambda p: np.lexsort((p[:, 1], p[:, 0]))
    assert np.allclose(full[key(full)], ref[key(ref)], atol=1e-6)


def test_points_are_uniform_over_seeds():
    """One sample, many seeds: film position, 1D and 2D draws (a set's point plus a hashed
    shift, and past the sets) are uniform (chi-square, 64 bins)."""
    n = 1 << 14
    s = make("pmj02bn", sample_count=16)
    seeds = dr.arange(mi.UInt32, n) * 0x9E3779B9
    st = s.start(mi.UInt32(5), mi.UInt32(3), 16, (8, 8), seeds)
    p = st.pixel_2d()
    u1, u2 = st.next_1d(), st.next_2d()
    for _ in range(5):
        u3 = st.next_2d()      # past the fifth set: a permuted index
    vals = [np.asarray(v, np.float64) for v in (p.x, p.y, u1, u2.x, u2.y, u3.x, u3.y)]
    for v in vals:
        assert chi2_uniform(v, 64) < CHI2_999[63]
    cells = np.floor(vals[3] * 8) * 8 + np.floor(vals[4] * 8)
    assert chi2_uniform(cells / 64 + 1e-9, 64) < CHI2_999[63]


def test_more_samples_than_the_sets_hold_is_an_error():
    import pbr
    s = make("pmj02bn", sample_count=16)
    with pytest.raises(ValueError, match=r"sampler: the 'pmj02bn' sampler takes at most 4096"):
        s.round_spp(8192)
    d = pbr.cornell_box(8, 4)
    d["sensor"]["sampler"] = {"type": "pmj02bn", "sample_count": 8192}
    with pytest.raises(pbr.SceneError, match=r"sensor\.sampler\.sample_count.*at most 4096"):
        pbr.load_dict(d)
