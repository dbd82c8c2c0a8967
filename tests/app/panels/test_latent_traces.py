"""The Latent Traces panel's heat image and scale."""
import numpy as np
import pytest
from app.panels.latent import diverging_lut, heat_image, latent_scale


def test_heat_image_is_row_per_dimension_newest_right():
    lut = diverging_lut(256)
    assert lut.shape == (256, 4) and lut[0, 2] > lut[0, 0] and lut[-1, 0] > lut[-1, 2]   # blue .. red
    v = np.zeros((10, 3))
    v[-1, 0] = 1.0        # newest tick, dimension 0: full positive
    v[0, 2] = -1.0        # oldest tick, dimension 2: full negative
    v[5, 1] = np.nan
    img = heat_image(v, 1.0, lut, columns=20)
    assert img.shape == (3, 20, 4)
    assert np.allclose(img[0, -1], lut[-1]) and np.allclose(img[2, 0], lut[0])
    assert np.allclose(img[1, 0], lut[127], atol=0.02)          # zero is the middle of the map
    assert np.allclose(img[1, 10, :3], 0.2, atol=0.03)          # NaN: dark grey
    out = np.empty((3, 20, 4), np.float32)
    assert heat_image(v, 1.0, lut, columns=20, out=out) is out


def test_heat_image_missing_cells_are_grey_and_the_rest_untouched():
    lut = diverging_lut(256)
    rng = np.random.default_rng(3)
    v = rng.normal(size=(40, 5))
    clean = heat_image(v, 1.5, lut, columns=40)
    v[[2, 9, 30], [0, 4, 1]] = (np.nan, np.inf, -np.inf)
    img = heat_image(v, 1.5, lut, columns=40)
    bad = np.zeros((5, 40), bool)
    bad[[0, 4, 1], [2, 9, 30]] = True
    assert np.array_equal(img[bad], np.tile(np.float32((0.2, 0.2, 0.22, 1.0)), (3, 1)))
    assert np.array_equal(img[~bad], clean[~bad])
    assert lut.shape == (256, 4)                                # the caller's table is not extended


def test_latent_scale():
    assert latent_scale(np.zeros((5, 3))) == 0.5
    assert latent_scale(np.full((5, 3), 4.0)) == pytest.approx(4.0)
    assert latent_scale(np.array([np.nan])) == 1.0
