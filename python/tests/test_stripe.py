"""omniscan.detect_stripe on numpy images (decoded by OpenCV): the same centres as omni-ridge,
and near the simulator's true stripe pixels."""
import cv2
import numpy as np
import pytest

import omniscan


def frames(sim):
    return omniscan.read_stream(sim["dir"] / "stripes.jsonl")["frames"]


def test_detect_stripe_equals_omni_ridge(sim):
    cam = omniscan.Camera.load(sim["camera"])
    for fr in frames(sim):
        image = cv2.imread(fr["image_path"], cv2.IMREAD_UNCHANGED)
        assert image.dtype == np.uint8 and image.shape == cam.image_size[::-1]
        ours = omniscan.detect_stripe(image, cam)
        np.testing.assert_array_equal(ours, fr["stripe"])


def test_detected_centres_are_near_the_true_stripe(sim):
    cam = omniscan.Camera.load(sim["camera"])
    by_seq = {fr["seq"]: fr for fr in frames(sim)}
    distances = []
    for rec in sim["truth"]:
        image = cv2.imread(by_seq[rec["seq"]]["image_path"], cv2.IMREAD_UNCHANGED)
        found = omniscan.detect_stripe(image, cam)[:, :2]
        true_px = np.array(rec["points"])[:, 3:5]
        assert len(found) > 20 and len(true_px) > 0
        # Distance from each found centre to the densely sampled true stripe.
        d = np.linalg.norm(found[:, None, :] - true_px[None, :, :], axis=2).min(axis=1)
        distances.append(d)
    d = np.concatenate(distances)
    # Measured: median 0.04 px, 95 % within 0.07 px (384 px idealised frames).
    assert np.median(d) < 0.1 and np.quantile(d, 0.95) < 0.3, (np.median(d), np.quantile(d, 0.95))


def test_sixteen_bit_images_and_ambient_subtraction():
    # A synthetic vertical Gaussian stripe at x = 40.3 px on a 96x96 frame, plus a flat ambient.
    x = np.arange(96.0)
    profile = 30000.0 * np.exp(-0.5 * ((x - 40.3) / 1.2) ** 2)
    stripe = np.tile(profile, (96, 1))
    ambient = np.full((96, 96), 5000, dtype=np.uint16)
    image = (stripe + ambient).astype(np.uint16)
    found = omniscan.detect_stripe(image, ambient=ambient, method="gauss")
    assert len(found) > 20
    rows = found[np.abs(found[:, 1] - 48.0) < 30.0]
    np.testing.assert_allclose(rows[:, 0], 40.3, atol=0.05)
    # The same stripe at 8 bits is found at the same place.
    found8 = omniscan.detect_stripe((stripe / 257.0).astype(np.uint8), method="gauss")
    np.testing.assert_allclose(np.median(found8[:, 0]), 40.3, atol=0.05)


def test_bad_images_and_settings_are_refused(sim):
    cam = omniscan.Camera.load(sim["camera"])
    with pytest.raises(TypeError, match="uint8 or uint16"):
        omniscan.detect_stripe(np.zeros((8, 8), dtype=np.float32))
    with pytest.raises(TypeError, match="RGB array"):
        omniscan.detect_stripe(np.zeros((8, 8, 4), dtype=np.uint8))
    with pytest.raises(TypeError, match="RGB array"):
        omniscan.detect_stripe(np.zeros((8, 8, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="no colour"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), laser="red")
    with pytest.raises(ValueError, match="drop bayer"):
        omniscan.detect_stripe(np.zeros((20, 30, 3), dtype=np.uint8), bayer="rggb")
    with pytest.raises(ValueError, match="not both"):
        omniscan.detect_stripe(np.zeros((20, 30, 3), dtype=np.uint8), laser="red", channel="red")
    with pytest.raises(ValueError, match="unknown Bayer order"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), bayer="rgbg")
    with pytest.raises(ValueError, match="even sides"):
        omniscan.detect_stripe(np.zeros((21, 30), dtype=np.uint8), bayer="rggb")
    with pytest.raises(ValueError, match="red or blue"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), bayer="rggb", bayer_sites=True, laser="green")
    with pytest.raises(ValueError, match="give its order with bayer"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), bayer_sites=True, laser="red")
    with pytest.raises(ValueError, match="camera's image"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), cam)
    with pytest.raises(ValueError, match="unknown method"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), method="magic")
    with pytest.raises(ValueError, match="ambient"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), ambient=np.zeros((20, 31), dtype=np.uint8))


def red_stripe_on_checks(size=128, centre=56.3, sigma=1.6):
    """A red Gaussian stripe (x = centre px, vertical) on lit grey paper with dark 16 px checks,
    blurred by the lens: in R - (G+B)/2 only the stripe is there."""
    y, x = np.mgrid[0:size, 0:size].astype(float)
    paper = np.where(((x // 16) + (y // 16)) % 2 == 0, 110.0, 25.0)
    laser = 100.0 * np.exp(-0.5 * ((x - centre) / sigma) ** 2)
    rgb = np.stack([paper + laser, paper + 0.1 * laser, paper + 0.1 * laser], axis=2)
    # The lens's blur, before the colour filters sample the image.
    rgb = cv2.GaussianBlur(rgb, (0, 0), 0.7)
    return np.clip(np.round(rgb), 0, 255).astype(np.uint8)


def test_colour_frames_by_laser_contrast_and_bayer_mosaic():
    rgb = red_stripe_on_checks()
    found = omniscan.detect_stripe(rgb, laser="red", method="gauss")
    assert len(found) > 100
    # Every point on the stripe (none on the checks' edges), within 0.05 px of it.
    np.testing.assert_allclose(found[:, 0], 56.3, atol=0.05)
    # A raw RGGB mosaic of the same frame, demosaiced: red is sampled one pixel in four, so the
    # stripe's place between the red columns moves its centre, by up to 0.11 px on average
    # along the stripe (0.18 px at worst) at these phases; at the red columns, by nothing.
    for centre, mean_error in ((56.0, 0.01), (56.3, 0.07), (56.5, 0.12), (57.3, 0.12)):
        rgb = red_stripe_on_checks(centre=centre)
        mosaic = np.empty(rgb.shape[:2], np.uint8)
        mosaic[0::2, 0::2] = rgb[0::2, 0::2, 0]
        mosaic[0::2, 1::2] = rgb[0::2, 1::2, 1]
        mosaic[1::2, 0::2] = rgb[1::2, 0::2, 1]
        mosaic[1::2, 1::2] = rgb[1::2, 1::2, 2]
        demosaiced = omniscan.detect_stripe(mosaic, bayer="rggb", laser="red", method="gauss")
        assert len(demosaiced) > 100
        assert abs(demosaiced[:, 0].mean() - centre) <= mean_error, (centre, demosaiced[:, 0].mean())
        np.testing.assert_allclose(demosaiced[:, 0], centre, atol=0.2)
        # Read at the red sites alone (every other row and column): one point per two rows, in
        # the frame's pixels. A stripe this narrow (4 px at half maximum) is sampled every 2 px
        # there, which moves it as much as the demosaicing did (+0.002, -0.054, -0.103, +0.085
        # px on average at these phases); wider ones gain (tests/ridge_truth.rs).
        sites = omniscan.detect_stripe(mosaic, bayer="rggb", bayer_sites=True, laser="red", method="gauss")
        assert len(sites) > 50
        assert np.all(np.abs((sites[:, 1] + 1) % 2 - 1) < 0.01), sites[:, 1]
        assert abs(sites[:, 0].mean() - centre) <= mean_error, (centre, sites[:, 0].mean())
        np.testing.assert_allclose(sites[:, 0], centre, atol=0.2)


def test_the_along_stripe_fit_refuses_short_stripes_as_omni_ridge_does(tmp_path):
    """A long stripe and an 8 px one (about 5 px of centres once its ends go): with the along-stripe fit, both refuse the short one's
    points (shorter than the fit's window) and give the same centres."""
    import json
    from conftest import run, tool

    y, x = np.mgrid[0:120, 0:160].astype(float)
    img = 200 * np.exp(-0.5 * ((x - 60 - 0.1 * y) / 1.5) ** 2) * ((y >= 10) & (y < 110))
    img += 200 * np.exp(-0.5 * ((x - 120) / 1.5) ** 2) * ((y >= 50) & (y < 58))
    img = np.round(img).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "f.png"), img)
    records = [{"type": "header", "format": "omniscan.stream", "version": 1, "producers": ["test"],
                "frames_dir": str(tmp_path)},
               {"type": "frame", "seq": 0, "path": "f.png", "alpha_deg": 0.0, "facet": 0},
               {"type": "status", "frames": 1, "frames_missing": 0, "complete": True, "errors": []}]
    (tmp_path / "s.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    run(tool("omni-ridge"), "--along-stripe", "3", tmp_path / "s.jsonl", "-o", tmp_path / "r.jsonl")
    ridge = omniscan.read_stream(tmp_path / "r.jsonl")["frames"][0]["stripe"]
    ours = omniscan.detect_stripe(img, along_stripe_px=3)
    np.testing.assert_array_equal(ours, ridge)
    near_short = lambda pts: np.abs(pts[:, 0] - 120) < 3
    assert near_short(omniscan.detect_stripe(img)).any(), "the short stripe is found without the fit"
    assert not near_short(ours).any() and len(ours) > 80, ours[:, :2]


def lopsided_stripe(centre, sheet_fwhm, share=0.17, length=4.0, blur=0.7, size=96, peaks=None):
    """A vertical stripe whose sheet is a Gaussian core with `share` of its light in a one-sided
    exponential tail `length` core sigma long (towards +x), its peak at x = `centre`, blurred by
    a Gaussian lens of sigma `blur` px and integrated over the pixels: computed here by numerical
    convolution on a 1/64 px grid, independently of omniscan's own model of the profile. The
    stripe peaks 200 levels above a background of 20, or `peaks` levels, one per row, clipped at
    255."""
    # An odd grid centred on 0, so that np.convolve's "same" keeps every profile in place.
    h = 1.0 / 64
    x = np.arange(-40 * 64, 40 * 64 + 1) * h
    gauss = lambda s: np.exp(-0.5 * (x / s) ** 2) / (s * np.sqrt(2 * np.pi))
    # The core sigma that gives the sheet its FWHM, and the sheet's peak, found numerically.
    def sheet(core):
        tail = np.where(x >= 0, np.exp(-x / (length * core)) / (length * core), 0.0)
        return (1 - share) * gauss(core) + share * np.convolve(gauss(core), tail, mode="same") * h
    lo, hi = 0.01, sheet_fwhm
    for _ in range(50):
        core = 0.5 * (lo + hi)
        s = sheet(core)
        above = x[s >= 0.5 * s.max()]
        lo, hi = (core, hi) if above[-1] - above[0] < sheet_fwhm else (lo, core)
    s = sheet(core)
    k = np.argmax(s)
    # The sheet's peak between grid points: the vertex of a parabola through the top three.
    peak = x[k] + 0.5 * h * (s[k - 1] - s[k + 1]) / (s[k - 1] - 2 * s[k] + s[k + 1])
    image = np.convolve(s, gauss(blur), mode="same") * h
    # Pixel k covers [k - 0.5, k + 0.5] about the stripe's peak at `centre`.
    at = x - peak + centre
    columns = np.array([image[(at >= k - 0.5) & (at < k + 0.5)].sum() * h for k in range(size)])
    if peaks is None:
        row = np.round(20 + 200 * columns / columns.max())
        return np.tile(row, (size, 1)).astype(np.uint8)
    rows = 20 + np.asarray(peaks, dtype=float)[:, None] * columns[None, :] / columns.max()
    return np.clip(np.round(rows), 0, 255).astype(np.uint8)


def test_a_known_laser_tail_leads_a_narrow_lopsided_stripe_to_its_peak():
    # A sheet 0.6 px wide under a 0.7 px lens: the blur makes most of the stripe's width, and the
    # stripe's own top shape undoes its shift of the lopsided peak to first order only.
    errors = {}
    for given in [None, (0.17, 4.0)]:
        found = []
        for centre in np.linspace(40.0, 41.0, 16, endpoint=False):
            pts = omniscan.detect_stripe(lopsided_stripe(centre, 0.6), optics_blur_px=0.7, laser_tail=given)
            inner = pts[(pts[:, 1] > 10) & (pts[:, 1] < 86)]
            assert len(inner) > 60
            found.append(np.mean(inner[:, 0]) - centre)
        errors[given] = np.mean(found)
    # Measured: +0.03 px towards the tail without the laser's profile, +0.008 with it (sheets of
    # 0.5 / 0.8 / 1.2 / 2 px: +0.033 / +0.025 / +0.004 / +0.002 without, +0.008 / +0.007 /
    # -0.006 / +0.006 with; from 3 px on the stripe's own top shape leads it either way).
    assert errors[None] > 0.02, errors
    assert abs(errors[(0.17, 4.0)]) < 0.012, errors
    # A list does as well as a tuple.
    listed = omniscan.detect_stripe(lopsided_stripe(40.3, 0.6), optics_blur_px=0.7, laser_tail=[0.17, 4.0])
    np.testing.assert_array_equal(listed, omniscan.detect_stripe(lopsided_stripe(40.3, 0.6), optics_blur_px=0.7,
                                                                 laser_tail=(0.17, 4.0)))
    with pytest.raises(ValueError, match="laser_tail: tail_weight"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), laser_tail=(0.95, 4.0))
    with pytest.raises(ValueError, match="laser_tail: expected"):
        omniscan.detect_stripe(np.zeros((20, 30), dtype=np.uint8), laser_tail=(0.2, 4.0, 1.0))


def test_a_known_laser_tail_leads_clipped_points_to_the_peak_by_their_unclipped_neighbours():
    # A 4 px sheet whose upper rows peak 120 levels above the background (unclipped) and whose
    # lower rows 700 (clipped at 255, 3 times over): the plateau's centre lies towards the tail.
    peaks = np.where(np.arange(96) < 48, 120.0, 700.0)
    errors = {}
    for given in [None, (0.17, 4.0)]:
        clipped, dim = [], []
        for centre in np.linspace(40.0, 41.0, 8, endpoint=False):
            img = lopsided_stripe(centre, 4.0, peaks=peaks)
            pts = omniscan.detect_stripe(img, optics_blur_px=0.7, laser_tail=given)
            # Rows that see at least 8 unclipped ones within 48 px along the stripe.
            clipped.append(np.mean(pts[(pts[:, 1] > 52) & (pts[:, 1] < 80), 0]) - centre)
            dim.append(np.mean(pts[(pts[:, 1] > 6) & (pts[:, 1] < 44), 0]) - centre)
        errors[given] = (np.mean(clipped), np.mean(dim))
    # Measured: clipped +0.231 px without the profile, +0.009 with it; the unclipped rows +0.002.
    assert errors[None][0] > 0.15, errors
    assert abs(errors[(0.17, 4.0)][0]) < 0.02 and abs(errors[(0.17, 4.0)][1]) < 0.015, errors


def test_a_laser_tail_is_measured_from_an_independently_drawn_stripe():
    # Stripes drawn by numpy's own convolution (lopsided_stripe), 6 px wide, 8-bit.
    for share, length in [(0.17, 4.0), (0.4, 1.5)]:
        img = lopsided_stripe(80.3, 6.0, share=share, length=length, size=160)
        stripe = omniscan.detect_stripe(img, optics_blur_px=0.7, max_width=30)
        tail = omniscan.measure_laser_tail(img, stripe, optics_blur_px=0.7)
        assert abs(tail["tail_weight"] - share) <= 0.03, tail
        assert abs(tail["tail_length"] / length - 1) <= 0.15, tail
        assert tail["profiles"] >= 100 and tail["residual_rms"] < 0.5 * tail["gaussian_residual_rms"], tail
    gaussian = lopsided_stripe(80.3, 6.0, share=0.0, size=160)
    with pytest.raises(ValueError, match="no tail stands out"):
        omniscan.measure_laser_tail(gaussian, omniscan.detect_stripe(gaussian, max_width=30), optics_blur_px=0.7)
    with pytest.raises(ValueError, match=r"stripe: expected an array of shape \(\.\.\., 5\)"):
        omniscan.measure_laser_tail(img, stripe[:, :2])
    with pytest.raises(ValueError, match="min_profiles"):
        omniscan.measure_laser_tail(img, stripe, min_profiles=2)


def test_one_stripe_per_column_drops_a_dim_copy_of_the_stripe():
    """A reflection of the stripe (a tenth as bright, 40 px below it over the same columns) is
    kept by default, dropped with one_stripe_per="column", and kept when rows are the scan lines
    (it shares none of them)."""
    y = np.arange(120.0)[:, None]
    stripe = 200.0 * np.exp(-0.5 * ((y - 40.3) / 1.5) ** 2)
    reflection = 20.0 * np.exp(-0.5 * ((y - 80.6) / 2.0) ** 2)
    image = np.broadcast_to(stripe + reflection, (120, 160)).astype(np.uint8)
    near = lambda pts, v: int((np.abs(pts[:, 1] - v) < 2.0).sum())  # noqa: E731
    every = omniscan.detect_stripe(image)
    assert near(every, 40.3) > 100 and near(every, 80.6) > 100
    one = omniscan.detect_stripe(image, one_stripe_per="column")
    assert near(one, 40.3) == near(every, 40.3) and near(one, 80.6) == 0
    np.testing.assert_array_equal(omniscan.detect_stripe(image, one_stripe_per="row"), every)
    with pytest.raises(ValueError, match="one_stripe_per: unknown scan line"):
        omniscan.detect_stripe(image, one_stripe_per="radial")
