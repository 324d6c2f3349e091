"""Per-region strength: a region at strength 0 keeps the target's own pixels
(warp and appearance alike), the others take the expression; bad regions: one line."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from mimica import MimicaError
from mimica.image import ImageAnalogy, read_image
from mimica.image.analogy import REGIONS
from mimica.image.io import luminance
from mimica.landmarks.detect2d import detect

YALE = Path(os.environ["MIMICA_DATA"]) / "yalefaces"


@pytest.fixture(scope="module")
def pair():
    s, x, t = (read_image(YALE / f) for f in ("subject01.normal.gif", "subject01.surprised.gif",
                                               "subject03.normal.gif"))
    return s, detect(s), x, detect(x), t, detect(t)


def _box(pts, idx, pad=4):
    p = pts[idx]
    return (int(p[:, 0].min()) - pad, int(p[:, 1].min()) - pad, int(p[:, 0].max()) + pad, int(p[:, 1].max()) + pad)


@pytest.mark.parametrize("method", ["shading", "vtc", "warp", "eri"])
def test_a_region_at_zero_keeps_its_pixels(pair, method):
    s, sp, x, xp, t, tp = pair
    an = ImageAnalogy(t, tp)
    full = an.transfer(luminance(s), sp, luminance(x), xp, method=method).image
    only_mouth = an.transfer(luminance(s), sp, luminance(x), xp, method=method,
                             strength={"all": 0.0, "mouth": 1.0}).image
    x0, y0, x1, y1 = _box(tp, np.r_[REGIONS["brows"], REGIONS["eyes"]])
    region = slice(max(y0, 0), y1), slice(max(x0, 0), x1)
    assert np.abs(full[region] - t[region]).max() * 255 > 5                 # the brows rise when all move
    assert np.abs(only_mouth[region] - t[region]).max() * 255 <= 1.0         # held at 0: the target's own
    mx0, my0, mx1, my1 = _box(tp, REGIONS["mouth"])
    mouth = slice(my0, my1), slice(mx0, mx1)
    assert np.abs(only_mouth[mouth] - t[mouth]).max() * 255 > 5              # the mouth still moves


def test_unknown_regions_and_strengths_are_refused(pair):
    s, sp, x, xp, t, tp = pair
    an = ImageAnalogy(t, tp)
    for bad, said in (({"ears": 1.0}, "unknown region 'ears'"), ({"mouth": 3.0}, "strength 3")):
        with pytest.raises(MimicaError, match=said):
            an.transfer(luminance(s), sp, luminance(x), xp, strength=bad)


def test_the_head_stays_or_follows_the_source(pair):
    """The source's expressive photo is its neutral moved 12 px right and 6 down: with head
    "still" the target stays as it is; with "follow" it moves by that motion taken into its own
    frame (a's scale), the points with it."""
    from mimica.image.warp import Similarity2D
    s, sp, _, _, t, tp = pair
    dx, dy = 12, 6
    moved = np.roll(np.roll(s, dy, axis=0), dx, axis=1)
    an = ImageAnalogy(t, tp)
    still = an.transfer(luminance(s), sp, luminance(moved), sp + [dx, dy], method="warp")
    assert np.abs(still.image - t)[40:-40, 40:-40].max() * 255 <= 1.0
    follow = an.transfer(luminance(s), sp, luminance(moved), sp + [dx, dy], method="warp", head="follow")
    step = Similarity2D.fit(sp, tp).linear(np.array([dx, dy], float))
    np.testing.assert_allclose(follow.points - still.points, np.broadcast_to(step, (68, 2)), atol=1e-6)
    sx, sy = int(round(step[0])), int(round(step[1]))
    shifted = np.roll(np.roll(t, sy, axis=0), sx, axis=1)
    assert np.median(np.abs(follow.image - shifted)[40:-40, 40:-40]) * 255 < 2.0
    with pytest.raises(MimicaError, match="head 'nod'"):
        an.transfer(luminance(s), sp, luminance(moved), sp, head="nod")


@pytest.mark.parametrize("method", ["shading", "warp"])
def test_one_eye_at_zero_keeps_its_pixels_while_the_other_moves(pair, method):
    """A side's own region: eye_left=0 (the subject's left, iBUG 42-47) keeps that eye's pixels
    within one grey level of the target's while the right eye takes the surprise."""
    from mimica.image.warp import polygon_mask
    s, sp, x, xp, t, tp = pair
    got = ImageAnalogy(t, tp).transfer(luminance(s), sp, luminance(x), xp, method=method,
                                       strength={"eye_left": 0.0}).image

    def change(region):
        inside, (x0, y0, x1, y1) = polygon_mask(tp[REGIONS[region]], t.shape[:2])
        return np.abs(got[y0:y1, x0:x1][inside] - t[y0:y1, x0:x1][inside]).max() * 255
    assert change("eye_left") <= 1.0
    assert change("eye_right") > 5


@pytest.fixture(scope="module")
def smiling_target():
    """Rendered ICT photos with exact truth: the target (identity004) already smiles at half the
    happiness shape; its resting face; the source (identity001) neutral and happy; the truth, the
    target at the whole happiness."""
    from mimica.image.ictphotos import LIGHT_RIGHT, ICTPhotos
    ph = ICTPhotos()
    return (ph.photo("identity001"), ph.photo("identity001", "happiness"),
            ph.photo("identity004", "happiness", LIGHT_RIGHT, amount=0.5), ph.photo("identity004", None, LIGHT_RIGHT),
            ph.photo("identity004", "happiness", LIGHT_RIGHT))


@pytest.mark.parametrize("method", ["shading", "warp"])
def test_from_neutral_moves_a_smiling_target_by_the_smiles_difference_only(smiling_target, method):
    """From the target's own resting face, a target that already smiles at 0.5 is moved by the rest
    of the source's smile (to 1.0: the truth), not by the whole smile on top of its own (1.5):
    points within half a pixel of the truth's, and the photo far closer to it than without."""
    from mimica.image import psnr
    from mimica.image.warp import align_to
    (s, sp), (x, xp), (t, tp), (_, rp), (f, fp) = smiling_target
    truth = align_to(f, fp, tp)
    stacked = ImageAnalogy(t, tp).transfer(s, sp, x, xp, method=method)
    an = ImageAnalogy(t, tp, rest_points=rp)
    got = an.transfer(s, sp, x, xp, method=method)
    assert np.abs(got.points - fp).max() < 0.5
    assert np.abs(stacked.points - fp).max() > 4                      # the smile added to the target's own
    m = got.mask > 0.5
    assert psnr(got.image, truth, m) > psnr(stacked.image, truth, m) + 3
    assert psnr(got.image, truth, m) > psnr(t, truth, m) + 3
    assert np.abs(an.transfer(s, sp, x, xp, method=method, strength=0).image - t).max() < 2e-3


def test_from_neutral_refuses_what_it_cannot_do(smiling_target):
    (s, sp), (x, xp), (t, tp), (_, rp), _ = smiling_target
    an = ImageAnalogy(t, tp, rest_points=rp)
    for method in ("vtc", "eri"):
        with pytest.raises(MimicaError, match=f"method {method}: from the target's resting face"):
            an.transfer(s, sp, x, xp, method=method)
    with pytest.raises(MimicaError, match="resting face: 68 finite"):
        ImageAnalogy(t, tp, rest_points=rp[:60])


def test_from_neutral_with_a_source_whose_neutral_already_smiles(smiling_target):
    """The source's 'neutral' already smiles at half the happiness, its expression at the whole:
    from the target's resting face the target is moved by the smile's difference only (to half
    the happiness: the truth rendered), as the relative transfer does."""
    from mimica.image import psnr
    from mimica.image.ictphotos import LIGHT_RIGHT, ICTPhotos
    from mimica.image.warp import align_to
    ph = ICTPhotos()
    s, sp = ph.photo("identity001", "happiness", amount=0.5)
    (_, _), (x, xp), _, (n, np_), _ = smiling_target
    h, hp = ph.photo("identity004", "happiness", LIGHT_RIGHT, amount=0.5)
    got = ImageAnalogy(n, np_, rest_points=np_).transfer(s, sp, x, xp)
    assert np.abs(got.points - hp).max() < 0.5
    m = got.mask > 0.5
    assert psnr(got.image, align_to(h, hp, np_), m) > psnr(n, align_to(h, hp, np_), m) + 5
