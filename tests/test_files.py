"""Reading and writing user-named files: caps, aliases, confined paths, output paths."""

from __future__ import annotations

import os

import pytest

import graspnet_torch as gt
from graspnet_torch.files import check_output_path, confined_file, parse_document, read_document
from graspnet_torch.paths import repo_root


def _doc(text: str, json_: bool = False):
    return parse_document(text.encode(), "f.yaml", json_, gt.ProblemError)


def test_plain_yaml_and_json_parse_and_yaml12_floats_are_numbers():
    assert _doc("a: [1, 2.5, 1e3, 1.0e308, -2e-3]") == {"a": [1, 2.5, 1000.0, 1e308, -0.002]}
    assert _doc('{"a": [1, 2]}', json_=True) == {"a": [1, 2]}


def test_aliases_deep_nesting_and_bad_bytes_are_refused():
    assert _doc("a: &x [1, 2]\nb: *x\n") == {"a": [1, 2], "b": [1, 2]}  # what yaml.safe_dump writes
    bomb = "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 10)}]\n" for k in range(1, 9))
    with pytest.raises(gt.ProblemError, match=r"expands to 12\d{8} values through YAML aliases"):
        _doc(bomb)
    with pytest.raises(gt.ProblemError, match="nested too deeply"):
        _doc("[" * 100_000 + "]" * 100_000, json_=True)
    with pytest.raises(gt.ProblemError, match=r"not UTF-8 text \(invalid byte at offset 3\)"):
        parse_document(b"a: \xff\n", "f.yaml", False, gt.ProblemError)
    with pytest.raises(gt.ProblemError, match="malformed YAML"):
        _doc("a: !!python/object:os.system {}\n")
    with pytest.raises(gt.ProblemError, match="unreadable value"):
        _doc('{"a": ' + "9" * 5000 + "}", json_=True)


def test_size_cap_is_checked_before_reading(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_bytes(b"#" * 2000)
    with pytest.raises(gt.ConfigError, match="2000 bytes; a robot config may have at most 1000 bytes"):
        read_document(path, "robot config", gt.ConfigError, max_bytes=1000)


def test_confined_paths(tmp_path):
    inside = tmp_path / "meshes" / "cup.stl"
    inside.parent.mkdir()
    inside.write_text("solid x\nendsolid x\n")
    assert confined_file("meshes/cup.stl", "w", (tmp_path,), gt.ProblemError) == inside.resolve()
    assert confined_file(str(inside), "w", (tmp_path,), gt.ProblemError) == inside.resolve()
    (tmp_path / "link.stl").symlink_to("/etc/hostname")
    messages = []
    for raw in ("/etc/hostname", "/etc/does-not-exist", "../../../../../../../etc/hostname", "link.stl"):
        with pytest.raises(gt.ProblemError, match="outside the file's folder") as info:
            confined_file(raw, "w", (tmp_path,), gt.ProblemError)
        messages.append(str(info.value).replace(raw, "<p>"))
    assert len(set(messages)) == 1
    assert confined_file("/etc/hostname", "w", (tmp_path,), gt.ProblemError, allow_outside=True).is_file()
    with pytest.raises(gt.ProblemError, match="file not found"):
        confined_file("meshes/none.stl", "w", (tmp_path,), gt.ProblemError)
    # the repository counts as inside
    assert confined_file("urdf/hand/hand.urdf", "w", (tmp_path, repo_root()), gt.ProblemError).is_file()


def test_output_paths(tmp_path):
    assert check_output_path(str(tmp_path / "new" / "deeper" / "r.json"), "out", gt.ConfigError)
    assert not (tmp_path / "new").exists()  # checking makes no folder
    assert os.listdir(tmp_path) == []  # and leaves no probe file
    (tmp_path / "file").write_text("keep")
    for bad, message in [(tmp_path, "is a directory"), (tmp_path / "file" / "r.json", "is not a folder"),
                         ("/dev/null", "is not a regular file"), ("", "expected a file path")]:
        with pytest.raises(gt.ConfigError, match=message):
            check_output_path(str(bad), "out", gt.ConfigError)
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    with pytest.raises(gt.ConfigError, match="broken link"):
        check_output_path(str(tmp_path / "dangling"), "out", gt.ConfigError)
    assert (tmp_path / "file").read_text() == "keep"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders; see the /proc case")
def test_read_only_folder_is_refused(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(gt.ConfigError, match="cannot write in"):
            check_output_path(str(folder / "r.json"), "out", gt.ConfigError)
    finally:
        folder.chmod(0o755)


def test_read_only_mount_is_refused_even_for_root():
    if not os.path.isdir("/proc/self"):
        pytest.skip("no /proc")
    with pytest.raises(gt.ConfigError, match="cannot write in /proc"):
        check_output_path("/proc/graspnet-test/r.json", "out", gt.ConfigError)


def test_names_too_long_for_the_file_system_are_refused(tmp_path):
    with pytest.raises(gt.ConfigError, match="is too long for the file system"):
        check_output_path(str(tmp_path / ("a" * 250)), "out", gt.ConfigError)
    with pytest.raises(gt.ConfigError, match="is too long for the file system"):
        check_output_path(str(tmp_path / ("b" * 300) / "r.json"), "out", gt.ConfigError)
    assert check_output_path(str(tmp_path / ("c" * 200)), "out", gt.ConfigError)
