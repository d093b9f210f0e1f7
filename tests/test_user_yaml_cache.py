"""user_files.load_yaml keeps the documents of the texts it read (a robot file is read several times by one
command): what it hands out is a copy, an error is raised each time naming the file it was asked for, and the
result is the same as a first read's."""

import pytest

from robstiff_drake import user_files
from robstiff_drake.errors import InputError

TEXT = "robot: irb6400\njoint_limits:\n  lower_deg: [-180, -70]\n  upper_deg: [180, 70]\n"


def test_a_second_read_is_a_copy_with_the_same_lines():
    doc1, lines1 = user_files.load_yaml(TEXT, "a.yaml")
    doc1["joint_limits"]["lower_deg"][0] = 0.0  # a caller changing its document
    lines1[("robot",)] = 99
    doc2, lines2 = user_files.load_yaml(TEXT, "b.yaml")
    assert doc2 == {"robot": "irb6400", "joint_limits": {"lower_deg": [-180, -70], "upper_deg": [180, 70]}}
    assert lines2 == {("robot",): 1, ("joint_limits",): 2, ("joint_limits", "lower_deg"): 3,
                      ("joint_limits", "upper_deg"): 4}


@pytest.mark.parametrize("source", ["first.yaml", "second.yaml"])
def test_an_error_is_raised_each_time_naming_the_file_asked_for(source):
    with pytest.raises(InputError) as e:
        user_files.load_yaml("a: 1\na: 2\n", source)
    assert str(e.value).startswith(f"{source}:2: duplicated key 'a'")


def test_a_large_text_is_not_kept(monkeypatch):
    monkeypatch.setattr(user_files, "_PARSED_MAX_CHARS", 10)
    monkeypatch.setattr(user_files, "_PARSED", {})
    doc, _ = user_files.load_yaml(TEXT, "big.yaml")
    assert doc["robot"] == "irb6400" and user_files._PARSED == {}
