"""The one atomic file write: whole new content, or the old file untouched and no stray file."""

from __future__ import annotations

import json

import pytest

from pirl._atomic import replacing, write_atomic, write_json


def test_text_bytes_and_json_are_written_whole(tmp_path):
    assert write_atomic(tmp_path / "a.txt", "héllo") == tmp_path / "a.txt"
    assert (tmp_path / "a.txt").read_text() == "héllo"
    write_atomic(tmp_path / "b.bin", b"\x00\x01")
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    write_json(tmp_path / "c.json", {"b": 1, "a": tmp_path}, sort_keys=True, default=str)
    text = (tmp_path / "c.json").read_text()
    assert text.index('"a"') < text.index('"b"') and json.loads(text)["a"] == str(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.bin", "c.json"]


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "summary.csv"
    path.write_text("old")
    with pytest.raises(OSError), replacing(path) as tmp:
        tmp.write_text("half")
        raise OSError("disk full")
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["summary.csv"]


def test_a_writer_that_picks_its_suffix_gets_the_temporary_name_asked_for(tmp_path):
    path = tmp_path / "model.zip"
    with replacing(path, tmp_path / "model.tmp.zip") as tmp:
        assert tmp.name == "model.tmp.zip"
        tmp.write_bytes(b"zip")
    assert path.read_bytes() == b"zip" and not tmp.exists()
