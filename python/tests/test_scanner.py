"""omniscan.Scanner and omniscan.triangulate against the simulator's ground truth, and
triangulate against omni-triangulate on the same stripes."""
import json

import numpy as np
import pytest

import omniscan


def test_true_points_lie_on_their_frames_light_planes(sim):
    scanner = omniscan.Scanner.load(sim["scanner"])
    assert (scanner.num_facets, scanner.num_lasers) == (12, 2)
    assert scanner.facet_angle_deg == pytest.approx(30.0)
    for rec in sim["truth"]:
        pts = np.array(rec["points"])
        for laser in (0, 1):
            lit = pts[pts[:, 5] == laser, :3]
            plane = scanner.light_plane(rec["alpha_deg"], rec["facet"], laser)
            assert np.linalg.norm(plane["normal"]) == pytest.approx(1.0)
            assert plane["normal"][2] >= 0.0
            # Every true point lit by this laser is on its plane (mm).
            np.testing.assert_allclose(lit @ plane["normal"] - plane["offset"], 0.0, atol=1e-6)


def test_light_planes_vectorised_equal_one_by_one(sim):
    scanner = omniscan.Scanner.load(sim["scanner"])
    alphas = np.array([[1.0, 7.5, 15.0], [22.0, 28.5, 29.9]])
    planes = scanner.light_planes(alphas, facet=3, laser=1)
    assert planes.shape == (2, 3, 4)
    for idx in np.ndindex(alphas.shape):
        p = scanner.light_plane(alphas[idx], 3, 1)
        np.testing.assert_array_equal(planes[idx], [*p["normal"], p["offset"]])
    with pytest.raises(ValueError, match="facet"):
        scanner.light_plane(10.0, facet=12)
    with pytest.raises(ValueError, match="laser 2"):
        scanner.light_plane(10.0, laser=2)


def test_triangulating_true_pixels_gives_the_true_points(sim):
    cam = omniscan.Camera.load(sim["camera"])
    scanner = omniscan.Scanner.load(sim["scanner"])
    total = 0
    for rec in sim["truth"]:
        pts = np.array(rec["points"])
        out = omniscan.triangulate(cam, scanner, pts[:, 3:5], rec["alpha_deg"], rec["facet"])
        # Grazing rays may be refused; every point kept is the true one, with its laser.
        assert len(out["xyz"]) >= 0.95 * len(pts)
        np.testing.assert_allclose(out["xyz"], pts[out["index"], :3], atol=1e-6, rtol=0)
        np.testing.assert_array_equal(out["laser"], pts[out["index"], 5])
        origins, _ = cam.pixel_to_ray(pts[out["index"], 3:5])
        np.testing.assert_allclose(out["range"], np.linalg.norm(out["xyz"] - origins, axis=1), atol=1e-6)
        refused = sum(out["rejected"][k] for k in ("no_ray", "grazing", "unlit"))
        assert refused + len(out["xyz"]) == len(pts)
        total += len(out["xyz"])
    assert total > 100


def test_triangulate_equals_omni_triangulate_on_the_same_stripes(sim):
    cam = omniscan.Camera.load(sim["camera"])
    scanner = omniscan.Scanner.load(sim["scanner"])
    with open(sim["dir"] / "points.jsonl") as f:
        frames = [r for r in map(json.loads, f) if r.get("type") == "frame"]
    assert sum(len(fr["points"]) for fr in frames) > 100
    for fr in frames:
        stripe = np.array(fr["stripe"]).reshape(-1, 5)
        out = omniscan.triangulate(cam, scanner, stripe[:, :2], fr["alpha_deg"], fr["facet"], lasers=fr["lasers"])
        cli = np.array(fr["points"]).reshape(-1, 6)
        np.testing.assert_allclose(out["xyz"], cli[:, :3], atol=1e-9, rtol=0)
        np.testing.assert_array_equal(out["laser"], cli[:, 3])
        np.testing.assert_array_equal(out["index"], cli[:, 5])


def test_grazing_threshold_and_bad_arguments(sim):
    cam = omniscan.Camera.load(sim["camera"])
    scanner = omniscan.Scanner.load(sim["scanner"])
    rec = sim["truth"][0]
    pts = np.array(rec["points"])[:, 3:5]
    strict = omniscan.triangulate(cam, scanner, pts, rec["alpha_deg"], rec["facet"], min_incidence_deg=89.0)
    assert strict["rejected"]["grazing"] == len(pts) and len(strict["xyz"]) == 0
    with pytest.raises(ValueError, match="incidence"):
        omniscan.triangulate(cam, scanner, pts, rec["alpha_deg"], min_incidence_deg=0.0)
    with pytest.raises(ValueError, match="alpha_deg"):
        omniscan.triangulate(cam, scanner, pts, 400.0)


def test_fixed_plane_scanner_triangulates_its_one_plane(sim):
    """A scanner.json of kind fixed_planes: the plane whatever the angle, true pixels on it
    triangulate to their points, polygon-only properties raise naming the kind."""
    cam = omniscan.Camera.load(sim["camera"])
    polygon = omniscan.Scanner.load(sim["scanner"])
    rec = sim["truth"][0]
    plane = polygon.light_plane(rec["alpha_deg"], rec["facet"], 0)
    doc = {"format": "omniscan.scanner", "version": 2,
           "transmitter": {"kind": "fixed_planes",
                           "planes": [{"laser": 0, "normal": plane["normal"].tolist(), "distance_mm": plane["offset"]}]}}
    scanner = omniscan.Scanner.from_json(json.dumps(doc), "fixed.json")
    assert (scanner.kind, scanner.num_lasers) == ("fixed_planes", 1)
    fixed = scanner.light_plane(3.0, facet=5, laser=0)
    assert set(fixed) == {"normal", "offset"}
    np.testing.assert_allclose(fixed["normal"], plane["normal"], atol=1e-12)
    with pytest.raises(ValueError, match="fixed_planes"):
        scanner.num_facets
    with pytest.raises(ValueError, match="laser 1"):
        scanner.light_plane(0.0, laser=1)
    pts = np.array(rec["points"])
    lit = pts[pts[:, 5] == 0]
    out = omniscan.triangulate(cam, scanner, lit[:, 3:5], alpha_deg=99.0, facet=40, lasers=[0])
    assert len(out["xyz"]) >= 0.95 * len(lit)
    np.testing.assert_allclose(out["xyz"], lit[out["index"], :3], atol=1e-6, rtol=0)
    doc["transmitter"]["kind"] = "galvo"
    with pytest.raises(ValueError, match='unknown transmitter kind "galvo"'):
        omniscan.Scanner.from_json(json.dumps(doc), "fixed.json")


def test_negative_indices_and_nan_pixels_name_their_argument(sim):
    cam = omniscan.Camera.load(sim["camera"])
    scanner = omniscan.Scanner.load(sim["scanner"])
    px = np.array([[250.0, 250.0]])
    for kwargs, name in (({"facet": -1}, "facet"), ({"lasers": [-1]}, "lasers")):
        with pytest.raises(ValueError, match=f"{name}: expected a whole number from 0, got -1"):
            omniscan.triangulate(cam, scanner, px, 16.0, **kwargs)
    with pytest.raises(ValueError, match="laser: expected a whole number from 0, got -1"):
        scanner.light_plane(16.0, laser=-1)
    with pytest.raises(ValueError, match="facet: expected"):
        scanner.light_planes([16.0], facet=-3)
    with pytest.raises(ValueError, match=r"pixels\[1\]: not a finite number"):
        omniscan.triangulate(cam, scanner, np.array([[250.0, 250.0], [np.nan, 250.0]]), 16.0)
