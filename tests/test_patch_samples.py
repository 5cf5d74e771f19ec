"""patch_samples (the compiled sampler of the exposure fit) against a direct NumPy reading of
the same definition: box means of ``prev`` on integer grids, box means of ``cur`` blended
bilinearly at the sub-pixel positions, the curvature weights and the clip/outside masks."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.diagnostics.exposure_frame import integral_frame, patch_samples


def _box_means(img: np.ndarray, k: int) -> np.ndarray:
    """Mean of the k x k box whose top-left pixel is (v, u), for every (v, u) where it fits."""
    f = img.astype(np.float64)
    h, w = f.shape
    out = np.zeros((h - k + 1, w - k + 1))
    for dv in range(k):
        for du in range(k):
            out += f[dv : dv + h - k + 1, du : du + w - k + 1]
    return out / (k * k)


def _reference(prev, cur, q0, base, frac, r, k, curv):
    clip0 = (prev <= 5) | (prev >= 250)
    clip1 = (cur <= 5) | (cur >= 250)
    m0, m1 = _box_means(prev, k), _box_means(cur, k)
    c0, c1 = _box_means(clip0.astype(float), k) > 0, _box_means(clip1.astype(float), k) > 0
    half, s = k // 2, 2 * r - 1
    xs, ys, ws, oks = [], [], [], []
    for (u, v), (bu, bv), (fx, fy) in zip(q0, base, frac, strict=True):
        # prev: (2r+1)^2 box centres around (u, v); the box of centre c starts at c - k // 2
        rows, cols = np.arange(v - r, v + r + 1) - half, np.arange(u - r, u + r + 1) - half
        inside0 = rows[0] >= 0 and cols[0] >= 0 and rows[-1] < m0.shape[0] and cols[-1] < m0.shape[1]
        p = m0[np.ix_(rows, cols)] if inside0 else np.zeros((s + 2, s + 2))
        b0 = c0[np.ix_(rows, cols)] if inside0 else np.ones((s + 2, s + 2), bool)
        rows1 = np.arange(bv - r + 1, bv + r + 1) - half
        cols1 = np.arange(bu - r + 1, bu + r + 1) - half
        inside1 = rows1[0] >= 0 and cols1[0] >= 0 and rows1[-1] < m1.shape[0] and cols1[-1] < m1.shape[1]
        g = m1[np.ix_(rows1, cols1)] if inside1 else np.zeros((s + 1, s + 1))
        b1 = c1[np.ix_(rows1, cols1)] if inside1 else np.ones((s + 1, s + 1), bool)
        c = p[1:-1, 1:-1]
        lap = p[2:, 1:-1] + p[:-2, 1:-1] + p[1:-1, 2:] + p[1:-1, :-2] - 4 * c
        y = ((1 - fy) * ((1 - fx) * g[:-1, :-1] + fx * g[:-1, 1:])
             + fy * ((1 - fx) * g[1:, :-1] + fx * g[1:, 1:]))
        bad1 = b1[:-1, :-1] | b1[:-1, 1:] | b1[1:, :-1] | b1[1:, 1:]
        xs.append(c.ravel())
        ys.append(y.ravel())
        ws.append((1.0 / (1.0 + (lap / curv) ** 2)).ravel())
        oks.append((~(b0[1:-1, 1:-1] | bad1)).ravel() & inside0 & inside1)
    return np.array(xs), np.array(ys), np.array(ws), np.array(oks)


@pytest.mark.parametrize("as_float", [False, True])
def test_patch_samples_match_the_definition(as_float: bool) -> None:
    rng = np.random.default_rng(3)
    h, w, k, r = 60, 80, 5, 3
    prev = rng.integers(20, 236, (h, w)).astype(np.uint8)
    cur = np.clip(prev.astype(int) + rng.integers(-20, 21, (h, w)), 0, 255).astype(np.uint8)
    prev[:, :6] = 255  # a clipped band at the left and a black one at the bottom
    cur[-5:, :] = 0
    n = 60
    q0 = np.stack([rng.integers(-3, w + 3, n), rng.integers(-3, h + 3, n)], axis=1)
    base = q0 + rng.integers(-2, 3, (n, 2))
    frac = rng.random((n, 2)).astype(np.float32)
    fp = integral_frame(prev.astype(np.float32) if as_float else prev, k)
    fc = integral_frame(cur.astype(np.float32) if as_float else cur, k)
    got = patch_samples(fp, fc, q0, base, frac, r, 3.0)
    x, y, wt, ok = _reference(prev, cur, q0, base, frac.astype(np.float64), r, k, 3.0)
    np.testing.assert_array_equal(got.usable, ok)
    assert 0.3 * ok.size < ok.sum() < 0.9 * ok.size  # both masked and usable samples
    np.testing.assert_allclose(got.x[ok], x[ok], rtol=0, atol=1e-9)
    # the fractions are float32, and so is 1 - f in the sampler (as the tracks give them)
    np.testing.assert_allclose(got.y[ok], y[ok], rtol=1e-6, atol=0)
    np.testing.assert_allclose(got.weight[ok], wt[ok], rtol=1e-9, atol=1e-12)


def test_patch_samples_no_points_and_mismatched_boxes() -> None:
    img = np.full((20, 20), 100, np.uint8)
    f = integral_frame(img, 3)
    empty = np.zeros((0, 2), np.intp)
    got = patch_samples(f, f, empty, empty, np.zeros((0, 2), np.float32), 3, 3.0)
    assert got.x.shape == (0, 25) and got.usable.shape == (0, 25)
    with pytest.raises(ValueError, match="different boxes"):
        patch_samples(f, integral_frame(img, 5), empty, empty, np.zeros((0, 2), np.float32), 3, 3.0)
