"""Image metrics (stages/evaluate/metrics.py) against independent computations with known answers.

References: closed forms on synthetic images (a constant offset c gives RMSE |c|; SSIM of two
constant images is (2ab + C1)/(a^2 + b^2 + C1)); a brute-force per-window SSIM written directly
from Wang et al. 2004 Eq. 13 with an explicitly built 2-D window; and the published CIEDE2000 test
pairs of Sharma, Wu & Dalal 2005 (Table 1 of that paper).
"""
import numpy as np
import pytest

from stages.evaluate import metrics as m

# Sharma, Wu & Dalal 2005, "The CIEDE2000 color-difference formula: implementation notes,
# supplementary test data, and mathematical observations", Table 1: (Lab1, Lab2, dE00).
SHARMA_2005 = [
    ((50.0000, 2.6772, -79.7751), (50.0000, 0.0000, -82.7485), 2.0425),
    ((50.0000, 3.1571, -77.2803), (50.0000, 0.0000, -82.7485), 2.8615),
    ((50.0000, 2.8361, -74.0200), (50.0000, 0.0000, -82.7485), 3.4412),
    ((50.0000, -1.3802, -84.2814), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, 0.0000, 0.0000), (50.0000, -1.0000, 2.0000), 2.3669),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0009), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0011), 7.2195),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0009, -2.4900), 4.8045),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0011, -2.4900), 4.7461),
    ((50.0000, 2.5000, 0.0000), (50.0000, 0.0000, -2.5000), 4.3065),
    ((50.0000, 2.5000, 0.0000), (73.0000, 25.0000, -18.0000), 27.1492),
    ((50.0000, 2.5000, 0.0000), (61.0000, -5.0000, 29.0000), 22.8977),
    ((50.0000, 2.5000, 0.0000), (56.0000, -27.0000, -3.0000), 31.9030),
    ((50.0000, 2.5000, 0.0000), (58.0000, 24.0000, 15.0000), 19.4535),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.1736, 0.5854), 1.0000),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((63.0109, -31.0961, -5.8663), (62.8187, -29.7946, -4.0864), 1.2630),
    ((61.2901, 3.7196, -5.3901), (61.4292, 2.2480, -4.9620), 1.8731),
    ((35.0831, -44.1164, 3.7933), (35.0232, -40.0716, 1.5901), 1.8645),
    ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
    ((90.8027, -2.0831, 1.4410), (91.1528, -1.6435, 0.0447), 1.4441),
    ((6.7747, -0.2908, -2.4247), (5.8714, -0.0985, -2.2286), 0.6377),
    ((2.0776, 0.0795, -1.1350), (0.9033, -0.0636, -0.5514), 0.9082),
]


def _img(seed, h=24, w=30):
    return np.random.default_rng(seed).random((h, w, 3))


# ------------------------------------------------------------------------------------------------
def test_rmse_constant_offset_is_the_offset():
    ref = _img(1)
    for c in (0.25, -0.125, 1e-3):
        assert m.rmse(ref + c, ref) == pytest.approx(abs(c), rel=1e-9)


def test_rmse_and_relmse_match_numpy_formulas():
    """Independent numpy evaluation of the two definitions on random images."""
    ref, test = _img(2), _img(3) * 1.7
    assert m.rmse(test, ref) == pytest.approx(np.sqrt(np.mean((test - ref) ** 2)), rel=1e-12)
    assert m.relmse(test, ref) == pytest.approx(np.mean((test - ref) ** 2 / (ref ** 2 + 0.01)), rel=1e-12)


def test_relmse_closed_form_on_constant_images():
    """Constant reference r and test r + c: relMSE = c^2 / (r^2 + 0.01) exactly."""
    ref = np.full((8, 9, 3), 0.3)
    assert m.relmse(ref + 0.1, ref) == pytest.approx(0.01 / (0.09 + 0.01), rel=1e-12)
    assert m.relmse(ref, ref) == 0.0


def test_metrics_of_identical_images():
    ref = _img(4, 32, 32)
    assert m.rmse(ref, ref) == 0.0
    assert m.ssim(m.ssim_input(ref), m.ssim_input(ref)) == pytest.approx(1.0, abs=1e-12)
    assert float(np.max(m.delta_e2000_map(ref, ref))) == 0.0


def test_mean_intensity_is_channel_mean():
    img = _img(5)
    np.testing.assert_allclose(m.mean_intensity(img), img.reshape(-1, 3).mean(axis=0), rtol=1e-12)


def test_luminance_and_ssim_input():
    img = _img(6)
    y = 0.2126 * img[..., 0] + 0.7152 * img[..., 1] + 0.0722 * img[..., 2]
    np.testing.assert_allclose(m.luminance(img), y, rtol=1e-12)
    # sRGB encoding of clipped luminance: the IEC 61966-2-1 piecewise curve
    enc = np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.clip(y, 0, 1) ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(m.ssim_input(img), enc, rtol=1e-12)
    assert m.ssim_input(img * 5.0).max() == pytest.approx(1.0)  # clipped to L = 1


# ------------------------------------------------------------------------------------------------
def test_ssim_of_constant_images_closed_form():
    """Both images flat: variances and covariance vanish, SSIM = (2ab + C1) / (a^2 + b^2 + C1)."""
    a, b = 0.6, 0.35
    x = np.full((16, 20), a)
    y = np.full((16, 20), b)
    c1 = (0.01 * 1.0) ** 2
    assert m.ssim(x, y) == pytest.approx((2 * a * b + c1) / (a * a + b * b + c1), rel=1e-10)


def test_ssim_offset_closed_form():
    """y = x + c with x varying: structure/contrast term is exactly 1, so each window gives
    (2 mx (mx + c) + C1) / (mx^2 + (mx + c)^2 + C1) with mx the window mean."""
    rng = np.random.default_rng(7)
    x = rng.random((20, 22)) * 0.5
    c = 0.2
    smap = m.ssim_map(x, x + c)
    g = m.gaussian_window()
    win = np.outer(g, g)
    c1 = 1e-4
    for (i, j) in [(0, 0), (3, 7), (9, 11)]:
        mx = np.sum(win * x[i:i + 11, j:j + 11])
        assert smap[i, j] == pytest.approx((2 * mx * (mx + c) + c1) / (mx * mx + (mx + c) ** 2 + c1), rel=1e-10)


def test_ssim_matches_brute_force_windows():
    """Brute-force Wang et al. 2004 Eq. 13 over every 11x11 window with an explicit 2-D Gaussian."""
    rng = np.random.default_rng(8)
    x = rng.random((15, 17))
    y = np.clip(x + 0.2 * rng.standard_normal(x.shape), 0, 1)
    sig = 1.5
    k = np.arange(11) - 5.0
    win = np.exp(-(k[:, None] ** 2 + k[None, :] ** 2) / (2 * sig * sig))
    win /= win.sum()
    c1, c2 = (0.01) ** 2, (0.03) ** 2
    vals = []
    for i in range(15 - 10):
        for j in range(17 - 10):
            px, py = x[i:i + 11, j:j + 11], y[i:i + 11, j:j + 11]
            mx, my = np.sum(win * px), np.sum(win * py)
            vx = np.sum(win * (px - mx) ** 2)
            vy = np.sum(win * (py - my) ** 2)
            cxy = np.sum(win * (px - mx) * (py - my))
            vals.append((2 * mx * my + c1) * (2 * cxy + c2) / ((mx * mx + my * my + c1) * (vx + vy + c2)))
    assert m.ssim(x, y) == pytest.approx(np.mean(vals), rel=1e-10)
    assert m.ssim(x, y) < 0.9  # noise lowers it


def test_ssim_refuses_images_smaller_than_window():
    with pytest.raises(ValueError):
        m.ssim(np.zeros((10, 30)), np.zeros((10, 30)))


# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("lab1,lab2,expected", SHARMA_2005)
def test_ciede2000_sharma_2005_pairs(lab1, lab2, expected):
    assert float(m.delta_e2000(lab1, lab2)) == pytest.approx(expected, abs=1e-4)
    assert float(m.delta_e2000(lab2, lab1)) == pytest.approx(expected, abs=1e-4)  # symmetric


def test_rgb_to_lab_white_and_grey():
    """sRGB white maps to L* = 100, a* = b* = 0 (D65); mid grey Y = 0.18 to L* = 116 Y^(1/3) - 16."""
    lab = m.rgb_to_lab(np.array([[1.0, 1.0, 1.0], [0.18, 0.18, 0.18]]))
    # a*, b* within 0.02: colour-science's sRGB matrix is rounded (IEC 61966-2-1 4-digit values)
    np.testing.assert_allclose(lab[0], [100.0, 0.0, 0.0], atol=2e-2)
    np.testing.assert_allclose(lab[1], [116 * 0.18 ** (1 / 3) - 16, 0.0, 0.0], atol=2e-2)


def test_delta_e_map_uniform_shift():
    """A uniform colour change gives the same dE00 at every pixel, equal to the single-pair value."""
    ref = np.tile(np.array([0.2, 0.4, 0.1]), (12, 13, 1))
    test = np.tile(np.array([0.25, 0.35, 0.1]), (12, 13, 1))
    d = m.delta_e2000_map(test, ref)
    one = float(m.delta_e2000(m.rgb_to_lab(test[0, 0]), m.rgb_to_lab(ref[0, 0])))
    np.testing.assert_allclose(d, one, rtol=1e-12)
    assert one > 1.0
