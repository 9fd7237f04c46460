"""omniscan.read_stream and omniscan.read_ply against independent readers: Python's json module
on the same lines (docs/FORMATS.md) and plyfile."""
import json
import os

import numpy as np
import plyfile
import pytest

import omniscan


def json_lines(path):
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def test_read_stream_matches_the_json_lines(sim):
    path = sim["dir"] / "points.jsonl"
    records = json_lines(path)
    stream = omniscan.read_stream(path)
    assert stream["header"]["format"] == "omniscan.stream"
    assert stream["header"]["producers"] == records[0]["producers"]
    frames = [r for r in records if r["type"] == "frame"]
    assert len(stream["frames"]) == len(frames) == 7
    for ours, theirs in zip(stream["frames"], frames):
        assert (ours["seq"], ours["alpha_deg"], ours["facet"], ours["path"]) == \
            (theirs["seq"], theirs["alpha_deg"], theirs["facet"], theirs["path"])
        np.testing.assert_array_equal(ours["stripe"], np.array(theirs["stripe"]).reshape(-1, 5))
        np.testing.assert_array_equal(ours["points"], np.array(theirs["points"]).reshape(-1, 6))
        assert os.path.isfile(ours["image_path"])
    assert stream["status"] == {k: v for k, v in records[-1].items() if k != "type"}
    assert stream["status"]["complete"] is True


def test_a_manifest_has_no_stripes_and_a_cut_stream_says_so(sim, tmp_path):
    manifest = omniscan.read_stream(sim["dir"] / "manifest.jsonl")
    assert all(fr["stripe"] is None and fr["points"] is None for fr in manifest["frames"])
    lines = (sim["dir"] / "stripes.jsonl").read_text().splitlines()
    (tmp_path / "cut.jsonl").write_text("\n".join(lines[:3]) + "\n")
    cut = omniscan.read_stream(tmp_path / "cut.jsonl")
    assert len(cut["frames"]) == 2
    assert cut["status"]["complete"] is False
    assert "cut short" in cut["status"]["errors"][0]


def test_bad_streams_name_the_file_and_line(tmp_path):
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"type":"header","format":"omniscan.stream","version":7}\n')
    with pytest.raises(omniscan.FormatError, match=r"bad\.jsonl: line 1.*version"):
        omniscan.read_stream(bad)
    bad.write_text('{"type":"header","format":"omniscan.stream","version":1}\n{"type":"frame","seq":0}\n')
    with pytest.raises(omniscan.FormatError, match=r"bad\.jsonl: line 2"):
        omniscan.read_stream(bad)


def test_read_ply_matches_plyfile(sim):
    path = sim["dir"] / "cloud.ply"
    ours = omniscan.read_ply(path)
    vertex = plyfile.PlyData.read(str(path))["vertex"]
    theirs = np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1).astype(np.float64)
    assert ours["xyz"].shape == theirs.shape and len(theirs) > 100
    np.testing.assert_array_equal(ours["xyz"], theirs)
    scalars = [p.name for p in vertex.properties if p.name not in ("x", "y", "z")]
    assert scalars and sorted(scalars) == sorted(k for k in ours if k != "xyz")
    for name in scalars:
        np.testing.assert_array_equal(ours[name], vertex[name].astype(np.float32))
    with pytest.raises(omniscan.FormatError, match=r"notply\.ply"):
        bad = path.parent / "notply.ply"
        bad.write_text("hello\n")
        omniscan.read_ply(bad)


def test_a_frames_laser_off_image_is_resolved_like_its_image(tmp_path):
    import json
    (tmp_path / "fr").mkdir()
    records = [{"type": "header", "format": "omniscan.stream", "version": 1, "producers": ["test"], "frames_dir": "fr"},
               {"type": "frame", "seq": 0, "path": "a.png", "alpha_deg": 1.0, "facet": 0, "ambient_path": "off.png"},
               {"type": "frame", "seq": 1, "path": "b.png", "alpha_deg": 2.0, "facet": 0},
               {"type": "status", "frames": 2, "frames_missing": 0, "complete": True, "errors": []}]
    (tmp_path / "s.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    with_off, without = omniscan.read_stream(tmp_path / "s.jsonl")["frames"]
    assert with_off["ambient_path"] == "off.png", "the record's field as written"
    assert with_off["ambient_image_path"] == tmp_path / "fr" / "off.png"
    assert with_off["image_path"] == tmp_path / "fr" / "a.png"
    assert without["ambient_image_path"] is None
