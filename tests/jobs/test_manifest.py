"""The job manifest as saved after each input: every change since the last save is on disk (only
changed entries are encoded again), one entry a line, and it reads back as it was written."""

from __future__ import annotations

import json

from glradial.jobs.manifest import Manifest


def test_each_save_holds_every_change_since_the_last(tmp_path):
    inputs = []
    for i in range(5):
        inputs.append(tmp_path / f"in{i}.txt")
        inputs[-1].write_text(str(i))
    out = tmp_path / "out"
    out.mkdir()
    manifest = Manifest(out, "correct", {"k1": -0.2})
    for source in inputs:
        manifest.start(source.name, source, manifest.input_digest(source.name, source), [source.name])
    manifest.save()
    for i, source in enumerate(inputs[:3]):
        manifest.finish(source.name, "done" if i != 1 else "failed", outputs=[source.name] if i != 1 else [], error=None if i != 1 else "bad")
        manifest.save()
        on_disk = json.loads((out / "manifest.json").read_text())["entries"]
        assert on_disk == json.loads(json.dumps(manifest.entries))  # the file is the state, after every save
    (out / "in0.txt").write_text("0")  # an output in DIR: complete needs it there
    text = (out / "manifest.json").read_text()
    assert len(text.splitlines()) == 2 + len(inputs)  # the head, one line per entry, the closing brace
    again = Manifest(out, "correct", {"k1": -0.2})
    assert again.entries == manifest.entries
    assert again.complete("in0.txt", inputs[0], manifest.input_digest("in0.txt", inputs[0]))
    assert not again.complete("in1.txt", inputs[1], manifest.input_digest("in1.txt", inputs[1]))
    again.finish("in1.txt", "done", outputs=["in1.txt"], error=None)
    again.save()
    assert json.loads((out / "manifest.json").read_text())["entries"]["in1.txt"]["status"] == "done"
