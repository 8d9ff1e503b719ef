"""The sample-data registry: names, hashes, MRSTEREO_DATA, downloads through pooch (from a local server)."""
from __future__ import annotations

import functools
import hashlib
import http.server
import re
import threading

import pytest

from mrstereo.cli import entry
from mrstereo.recordings import samples as data


def test_registry_names_every_file_once_with_a_source_and_a_sha256():
    paths = [f.path for f in data._FILES]
    assert len(paths) == len(set(paths)) == 93 + 22 + 15           # + KITTI raw, EuRoC ASL
    for name in data.NAMES:
        scene = data.scene(name)
        assert scene.files and scene.description
        for f in scene.files:
            assert re.fullmatch(r"[0-9a-f]{64}", f.sha256)
            assert re.fullmatch(r"[\w.-]+/[\w.-]+", f.repository) and re.fullmatch(r"[0-9a-f]{7,40}", f.commit)
            assert f.url == f"https://raw.githubusercontent.com/{f.repository}/{f.commit}/{f.source_path}"
    assert sum(len(data.scene(n).files) for n in data.NAMES) == len(paths)   # every file in one scene
    with pytest.raises(ValueError, match="unknown sample data 'bogus'; known: tsukuba"):
        data.scene("bogus")


@pytest.mark.sample_data(*data.NAMES)
def test_local_copy_matches_the_registry_hashes():
    for name in data.NAMES:
        assert data.verify(name) == [], name


def test_mrstereo_data_is_used_as_is(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(data.ENV_VAR, str(tmp_path))
    assert data.data_root() == tmp_path
    assert data.local_path("teddy") == tmp_path / "middlebury2003" / "teddy"
    assert not data.is_available("teddy")
    with pytest.raises(FileNotFoundError, match=f"{data.ENV_VAR}=.* has no .*middlebury2003/teddy/"):
        data.fetch("teddy")
    assert not (tmp_path / "middlebury2003").exists()        # nothing downloaded into a user's copy
    assert entry(["data", "path", "teddy"]) == 2              # not there: an error naming the fetch command
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "mrstereo data fetch teddy" in err
    for f in data.scene("teddy").files:                       # complete: its folder
        (tmp_path / f.path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / f.path).write_bytes(b"")
    assert entry(["data", "path", "teddy"]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "middlebury2003" / "teddy")


@pytest.fixture
def served(tmp_path, monkeypatch):
    """A fake two-file scene served over HTTP from a local folder; the cache in tmp_path/cache."""
    source = tmp_path / "server"
    source.mkdir()
    contents = {"fake/a.txt": b"left view\n", "fake/sub/b.bin": bytes(range(256)) * 4}
    rows = []
    for path, content in contents.items():
        name = path.replace("/", "_")
        (source / name).write_bytes(content)
        rows.append(data.SampleFile(path, "owner/repo", "0123456", name, hashlib.sha256(content).hexdigest()))
    monkeypatch.setattr(data, "_FILES", data._FILES + tuple(rows))
    monkeypatch.setitem(data.SCENES, "fake", "fake")
    monkeypatch.delenv(data.ENV_VAR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(source))
    handler.log_message = lambda *args: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    monkeypatch.setattr(data, "_url", lambda f: f"http://127.0.0.1:{server.server_port}/{f.source_path}")
    yield source, contents, server
    server.shutdown()
    server.server_close()


def test_fetch_downloads_into_the_cache_and_checks_each_sha256(served, tmp_path):
    source, contents, server = served
    assert data.data_root() == tmp_path / "cache" / "mrstereo"
    assert not data.is_available("fake")
    folder = data.fetch("fake")
    assert folder == tmp_path / "cache" / "mrstereo" / "fake" and data.is_available("fake")
    for path, content in contents.items():
        assert (data.data_root() / path).read_bytes() == content
    assert data.verify("fake") == []
    server.shutdown()                                      # a second fetch needs no server
    assert data.fetch("fake") == folder


def test_fetch_refuses_a_file_whose_sha256_differs(served):
    source, contents, _ = served
    (source / "fake_sub_b.bin").write_bytes(b"tampered")
    with pytest.raises(ValueError, match="(?i)hash"):
        data.fetch("fake")
    assert not (data.data_root() / "fake" / "sub" / "b.bin").exists()


def test_cli_fetch_and_list(served, capsys):
    assert entry(["data", "fetch", "fake", "--quiet"]) == 0
    assert capsys.readouterr().out.strip() == f"fake: {data.data_root() / 'fake'}"
    assert entry(["data", "list", "--verify"]) == 0
    line = next(l for l in capsys.readouterr().out.splitlines() if l.startswith("fake "))
    assert "verified" in line and "2 files" in line
    assert entry(["data", "fetch", "nope"]) == 2
    assert capsys.readouterr().err.startswith("mrstereo: error: unknown sample data 'nope'")


def test_fetch_offline_is_one_line(served, capsys, monkeypatch):
    source, _, server = served
    port = server.server_port
    server.shutdown()
    server.server_close()                                  # nothing listens there any more: as offline
    monkeypatch.setattr(data, "_url", lambda f: f"http://127.0.0.1:{port}/{f.source_path}")
    assert entry(["data", "fetch", "fake", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mrstereo: error: could not download sample data 'fake'") and err.count("\n") == 1


def test_a_csv_cut_to_the_scenes_images_is_fetched_and_checked(served, tmp_path, monkeypatch):
    source, _, server = served
    upstream = b"#timestamp [ns],filename\n1,1.png\n2,2.png\n3,3.png\n"
    (source / "data.csv").write_bytes(upstream)
    (source / "2.png").write_bytes(b"two")
    cut = b"#timestamp [ns],filename\n2,2.png\n"
    rows = (data.SampleFile("asl/cam0/data/2.png", "owner/repo", "0123456", "2.png", hashlib.sha256(b"two").hexdigest()),
            data.SampleFile("asl/cam0/data.csv", "owner/repo", "0123456", "data.csv", hashlib.sha256(cut).hexdigest(),
                            "listed rows"))
    monkeypatch.setattr(data, "_FILES", data._FILES + rows)
    monkeypatch.setitem(data.SCENES, "asl", "asl")
    folder = data.fetch("asl")
    assert (folder / "cam0" / "data.csv").read_bytes() == cut and data.verify("asl") == []
    assert sorted(p.name for p in data.data_root().iterdir() if p.name.startswith(".")) == []    # no temporaries
    (folder / "cam0" / "data.csv").unlink()
    (source / "data.csv").write_bytes(upstream.replace(b"2,2.png", b"2,2.png,x"))                 # upstream changed
    with pytest.raises(ValueError, match="hash differs"):
        data.fetch("asl")
    assert not (folder / "cam0" / "data.csv").exists()


def test_the_euroc_and_kitti_raw_samples_are_in_the_registry():
    for name, folder in (("euroc-asl-sample", "euroc_asl_sample"), ("kitti-raw-sample", "kitti_raw_sample")):
        entry = data.scene(name)
        assert entry.folder == folder and entry.description
        if data.is_available(name):
            assert data.verify(name) == []
