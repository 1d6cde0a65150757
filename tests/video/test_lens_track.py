"""The lens track keeps whole lenses: principal point and pixel aspect survive save and load."""

from __future__ import annotations

import json
import re
from fractions import Fraction

import numpy as np
import pytest

from glradial import Lens, LensTrackError
from glradial.video.lens_track import LensTrack, load_lens_track


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_principal_point_and_aspect_round_trip(tmp_path, suffix):
    n = 3
    geometry = np.array([[0.01, -0.02, 1.0], [0.0, 0.0, 1.0], [-0.015, 0.005, 1.01]])
    lens = np.array([[-0.2, 0.03], [-0.25, 0.05], [-0.1, 0.0]])
    track = LensTrack(Fraction(25), (640, 360), np.zeros(n, np.int64), lens, np.full((n, 2), np.nan),
                      np.full(n, np.nan), geometry=geometry)
    path = track.save(tmp_path / f"track{suffix}")
    back = load_lens_track(path, Fraction(25), (640, 360))
    for i in range(n):
        assert back.lens_for(i) == Lens(*lens[i], *geometry[i])
    # maps of the read lens equal those of the written one (the principal point moves them)
    np.testing.assert_array_equal(back.lens_for(0).maps((640, 360))[0], Lens(*lens[0], *geometry[0]).maps((640, 360))[0])


def test_a_track_without_the_columns_reads_centred(tmp_path):
    path = tmp_path / "old.csv"
    path.write_text("frame,k1,k2\n0,-0.2,0.03\n1,-0.2,0.03\n")
    track = load_lens_track(path, Fraction(25), (640, 360))
    assert track.lens_for(1) == Lens(-0.2, 0.03)


def test_a_bad_principal_point_names_the_line(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("frame,k1,k2,cx\n0,-0.2,0.03,0\n1,-0.2,0.03,abc\n")
    with pytest.raises(ValueError, match="line 3: cx 'abc' is not a number"):
        load_lens_track(path, Fraction(25), (640, 360))


@pytest.mark.parametrize("text, message", [
    ("frame,k1\n0,0.1\n", "line 1: the header lacks the column(s) k2"),
    ("frame,k1,k2\n0,-0.1,0\n1,abc,0\n", "line 3: k1 'abc' is not a number"),
    ("frame,k1,k2,applied\n0,-0.1,0,2\n", "line 2: applied: 2.0 is not one of [0, 1]"),
    ("frame,k1,k2,shot\n0,-0.1,0,1.5\n", "line 2: shot: 1.5 is not of type 'integer'"),
    ("frame,k1,k2\n0,,0\n", "line 2: 'k1' is a required property"),
    ("frame,k1,k2\n0,-3,0\n", "line 2: lens k1=-3"),
])
def test_every_bad_track_raises_the_promised_type(tmp_path, text, message):
    """The module promises :class:`LensTrackError` (still a ``ValueError``) for any bad row."""
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(LensTrackError, match=re.escape(message)):
        load_lens_track(path, Fraction(25), (640, 360))


def test_a_track_shorter_than_the_video_raises_the_promised_type(tmp_path):
    path = tmp_path / "short.csv"
    path.write_text("frame,k1,k2\n0,-0.1,0\n")
    track = load_lens_track(path, Fraction(25), (640, 360))
    with pytest.raises(LensTrackError, match="the lens track has 1 frames; the video has more"):
        track.lens_for(1)
    assert issubclass(LensTrackError, ValueError)


@pytest.mark.parametrize("document, message", [
    ({"frames": [{"frame": 0, "k1": -0.1, "k2": 0}, {"frame": 1, "k1": "x", "k2": 0}]},
     "frames[1].k1: 'x' is not of type 'number'"),
    ({"frame": []}, "'frames' is a required property"),
    ({"frames": [{"frame": 0, "k1": -0.1, "k2": 0, "uncertainty_px": -2}]}, "frames[0].uncertainty_px: -2 is less than"),
])
def test_a_json_track_is_checked_against_the_schema(tmp_path, document, message):
    """JSON tracks follow the ``lens_track`` schema (glradial/data/lens_track.schema.json): the
    error names the file and the field."""
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(document))
    with pytest.raises(LensTrackError, match=re.escape(f"lens track {str(path)!r}: {message}")):
        load_lens_track(path, Fraction(25), (640, 360))


def test_what_the_track_writes_follows_its_schema(tmp_path):
    """Every row and key the writer produces (JSON) validates against the schema it is read with."""
    import jsonschema

    from glradial.schemas import schema

    n = 4
    track = LensTrack(Fraction(25), (640, 360), np.arange(n) // 2, np.tile([-0.2, 0.03], (n, 1)),
                      np.tile([-0.21, 0.031], (n, 1)), np.full(n, 1.0), uncertainty_px=np.full(n, 2.5), method=["net"] * n)
    document = json.loads(track.save(tmp_path / "t.json").read_text())
    jsonschema.Draft202012Validator(schema("lens_track")).validate(document)
    row_keys = set(schema("lens_track")["$defs"]["row"]["properties"])
    assert set(document["frames"][0]) == row_keys
