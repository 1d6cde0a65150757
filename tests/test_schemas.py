"""The JSON Schemas glradial ships (glradial/data/*.schema.json) are valid draft 2020-12 schemas,
describe what glradial itself writes, and turn a bad document into an error naming the file and the
field; the training-config schema covers every shipped config and the fields of net.train's
TrainConfig exactly."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import jsonschema
import pytest

from glradial.schemas import SCHEMAS, schema, validate, validate_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", SCHEMAS)
def test_every_schema_is_a_valid_draft_2020_12_schema(name):
    jsonschema.Draft202012Validator.check_schema(schema(name))
    assert schema(name)["$schema"] == "https://json-schema.org/draft/2020-12/schema"


def test_a_string_for_steps_is_refused_naming_the_field():
    with pytest.raises(ValueError, match="^training config 'run.json': steps: '100' is not of type 'integer'$"):
        validate_config({"steps": "100"}, "training config 'run.json'")
    with pytest.raises(ValueError, match="panoramas.seeds"):
        validate_config({"panoramas": {"kind": "stadium", "seeds": {"split": "train", "n": 0}}})
    with pytest.raises(ValueError, match="unknown key\\(s\\) 'stpes'; accepted: amp, augment, augment_workers, batch_size"):
        validate_config({"stpes": 100})
    validate_config({"steps": 100, "val_panoramas": None})


def test_the_shipped_training_configs_and_trainconfig_follow_the_schema():
    pytest.importorskip("torch")
    from net.train import TrainConfig, load_config_dict

    configs = sorted((ROOT / "net" / "configs").glob("*.json"))
    assert len(configs) >= 10
    for path in configs:
        validate_config(load_config_dict(path), f"training config {path.name!r}")
    assert set(schema("train_config")["properties"]) == {f.name for f in fields(TrainConfig)}
    defaults = json.loads(json.dumps({f.name: getattr(TrainConfig(), f.name) for f in fields(TrainConfig)}))
    validate_config(defaults, "TrainConfig()")


def test_glradial_s_own_outputs_are_valid_lens_files(tmp_path, capsys):
    """What 'glradial convert --json' and a LensEstimate's as_dict (estimate --json) print reads back."""
    from glradial.cli import main
    from glradial.estimation.lens_estimate import LensEstimate

    assert main(["convert", "--from", "width", "--to", "opencv", "--size", "1920x1080", "--focal", "1500",
                 "--json", "-0.2", "0.03"]) == 0
    convert = json.loads(capsys.readouterr().out)
    validate(convert, "lens_file", "convert --json", "convert")
    validate(convert, "lens_file", "convert --json")
    estimate = LensEstimate(-0.2, 0.03, method="lines", uncertainty_px=3.0, chains=4)
    validate({"path": "a.png", **estimate.as_dict()}, "lens_file", "estimate --json", "numbers")
    opencv = {"camera_matrix": convert["camera_matrix"], "dist_coeffs": convert["dist_coeffs"], "size": [1920, 1080]}
    validate(opencv, "lens_file", "opencv", "opencv")
    with pytest.raises(ValueError, match="^f: camera_matrix\\[1\\]: \\[0, 1\\] is too short"):
        validate(dict(opencv, camera_matrix=[[1, 0, 0], [0, 1], [0, 0, 1]]), "lens_file", "f", "opencv")


def test_net_train_refuses_a_config_whose_steps_is_a_string(tmp_path):
    """The trainer itself checks its config against the schema (not only validate_config)."""
    pytest.importorskip("torch")
    from net.train import TrainConfig

    path = tmp_path / "run.json"
    path.write_text('{"steps": "100"}')
    with pytest.raises(ValueError, match=r"run\.json.*steps: '100' is not of type 'integer'"):
        TrainConfig.from_json(path)
