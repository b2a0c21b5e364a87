"""Fetching Event Camera Dataset sequences from a local HTTP server: verified, resumed after
damage or interruption, opened with --dataset ecd:NAME; and the registry itself."""

import json
import socket

import pytest

from eas_vo.datasets import ecd_catalogue
from eas_vo.errors import DataError, EasVoError
from helpers import closed_port_url, publish_sequences, run_eas_vo


@pytest.fixture
def site(data_server, short_sequence, tmp_path, monkeypatch):
    """The short simulated sequence published as `seq_a` on the local server, with a test
    registry, a private data folder and the environment pointing at them."""
    folder, url, faults, hits = data_server
    registry = tmp_path / "registry.txt"
    md5s = publish_sequences(folder, {"seq_a": short_sequence}, registry)
    env = {"EAS_VO_DATA_URL": url, "EAS_VO_DATA_REGISTRY": str(registry), "EAS_VO_DATA_DIR": str(tmp_path / "data")}
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    return tmp_path / "data", md5s, faults, hits


def _leftovers(data):
    return sorted(p.name for p in data.iterdir()) if data.exists() else []


def test_a_fetched_sequence_is_verified_kept_once_and_runs_as_ecd_name(site, tmp_path):
    data, md5s, _, hits = site
    import os

    done = run_eas_vo("fetch", "seq_a", env=dict(os.environ))
    assert done.returncode == 0, done.stderr
    assert "fetching seq_a.zip (" in done.stderr and "MB" in done.stderr
    assert _leftovers(data) == ["seq_a.zip"] and hits["seq_a.zip"] == 1
    assert run_eas_vo("fetch", "ecd:seq_a", env=dict(os.environ)).returncode == 0
    assert hits["seq_a.zip"] == 1  # already there and whole: not downloaded again
    out = tmp_path / "run"
    ran = run_eas_vo(
        "run",
        "--dataset",
        "ecd:seq_a",
        "--frontend",
        "eas",
        "--duration",
        "1",
        "--out",
        str(out),
        "--quiet",
        env=dict(os.environ),
    )
    assert ran.returncode == 0, ran.stderr
    assert json.loads((out / "metrics.json").read_text())["frames"] > 10


def test_ecd_name_fetches_a_missing_sequence_before_opening_it(site):
    from eas_vo.registry import open_dataset

    data, md5s, _, hits = site
    dataset = open_dataset("ecd:seq_a")
    assert dataset.label == str(data / "seq_a.zip") and len(dataset.frame_times()) > 20 and hits["seq_a.zip"] == 1


def test_a_corrupted_download_is_detected_and_fetched_again(site):
    data, md5s, faults, hits = site
    faults["seq_a.zip"] = ["corrupt"]
    path = ecd_catalogue.fetch("seq_a")
    assert hits["seq_a.zip"] == 2 and ecd_catalogue.fetch("seq_a") == path and _leftovers(data) == ["seq_a.zip"]


def test_a_damaged_file_in_place_is_replaced(site):
    data, md5s, _, hits = site
    path = ecd_catalogue.fetch("seq_a")
    path.write_bytes(path.read_bytes()[:-10])
    ecd_catalogue.fetch("seq_a")
    assert hits["seq_a.zip"] == 2 and _leftovers(data) == ["seq_a.zip"]
    import hashlib

    assert hashlib.md5(path.read_bytes()).hexdigest() == md5s["seq_a"]


def test_an_interrupted_download_leaves_nothing_and_succeeds_on_retry(site):
    import os

    data, md5s, faults, hits = site
    faults["seq_a.zip"] = ["drop"] * 3  # more than pooch's retries
    failed = run_eas_vo("fetch", "seq_a", env=dict(os.environ))
    assert failed.returncode == 1 and failed.stderr.count("\n") == 2, failed.stderr  # the notice, then one error line
    assert "download failed, nothing was kept" in failed.stderr and "Traceback" not in failed.stderr
    assert _leftovers(data) == []  # no half file under the final name, and no temporary either
    assert run_eas_vo("fetch", "seq_a", env=dict(os.environ)).returncode == 0
    assert _leftovers(data) == ["seq_a.zip"] and hits["seq_a.zip"] == 4


def test_a_download_that_never_matches_is_an_error_and_keeps_nothing(site):
    data, _, faults, hits = site
    faults["seq_a.zip"] = ["corrupt"] * 3
    with pytest.raises(EasVoError, match="does not match its MD5"):
        ecd_catalogue.fetch("seq_a")
    assert _leftovers(data) == []


def test_unknown_names_are_refused_before_any_download(site):
    import os

    _, _, _, hits = site
    done = run_eas_vo("fetch", "seq_a", "hdr_boxez", env=dict(os.environ))
    assert done.returncode == 1 and "hdr_boxez: no dataset plugin can fetch it (known: seq_a)" in done.stderr
    assert hits["seq_a.zip"] == 0


def test_the_built_in_registry_lists_the_datasets_25_sequences(monkeypatch):
    monkeypatch.delenv("EAS_VO_DATA_REGISTRY", raising=False)
    md5s = ecd_catalogue.registry()
    assert len(md5s) == 25
    assert md5s["hdr_boxes"] == "d9b2d0a74c69072abf42477376ee45c3"
    assert md5s["hdr_poster"] == "3e91a58daa8b279f764db4319f5c901c"
    assert md5s["shapes_rotation"] == "1f629824940bd79cb8b6bfeb0d086c7e"
    assert {"slider_depth", "urban", "calibration", "office_zigzag"} <= set(md5s)


@pytest.mark.parametrize(
    "text, line",
    [("a 0123456789abcdef0123456789abcdef\nb 12\n", 2), ("# mirror\n\nc/d 0123456789abcdef0123456789abcdef\n", 3)],
)
def test_a_bad_registry_line_is_named(tmp_path, monkeypatch, text, line):
    path = tmp_path / "reg.txt"
    path.write_text(text)
    monkeypatch.setenv("EAS_VO_DATA_REGISTRY", str(path))
    with pytest.raises(DataError, match=f"reg.txt:{line}"):
        ecd_catalogue.registry()


def test_a_registry_with_a_byte_order_mark_and_crlf_line_ends_reads_as_plain_text(tmp_path, monkeypatch):
    path = tmp_path / "reg.txt"
    path.write_bytes(
        b"\xef\xbb\xbftiny 0123456789abcdef0123456789abcdef\r\n# a mirror's\r\nother 0123456789ABCDEF0123456789abcdef\r\n"
    )
    monkeypatch.setenv("EAS_VO_DATA_REGISTRY", str(path))
    assert ecd_catalogue.registry() == {
        "tiny": "0123456789abcdef0123456789abcdef",
        "other": "0123456789abcdef0123456789abcdef",
    }


def test_the_suite_cannot_reach_the_internet():
    with pytest.raises(OSError, match="no network outside loopback"):
        socket.create_connection(("93.184.216.34", 80), timeout=1)


def test_a_wrong_data_folder_or_url_is_one_line_before_any_download(site, tmp_path, monkeypatch):
    _, _, _, hits = site
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(EasVoError, match="the data folder .* is a file"):
        ecd_catalogue.fetch("seq_a", tmp_path / "a_file")
    monkeypatch.setenv("EAS_VO_DATA_URL", "ftpx://127.0.0.1/")
    with pytest.raises(EasVoError, match="expected an http://, https:// or ftp:// address"):
        ecd_catalogue.fetch("seq_a")
    assert hits["seq_a.zip"] == 0


def test_a_file_the_server_lacks_or_a_server_down_is_one_line_before_any_notice(site, tmp_path, monkeypatch):
    import os

    data, md5s, _, hits = site
    registry = tmp_path / "with_missing.txt"
    registry.write_text(f"seq_a {md5s['seq_a']}\nseq_gone 0123456789abcdef0123456789abcdef\n")
    monkeypatch.setenv("EAS_VO_DATA_REGISTRY", str(registry))
    missing = run_eas_vo("fetch", "seq_gone", env=dict(os.environ))
    assert missing.returncode == 1 and missing.stderr.count("\n") == 1, missing.stderr
    assert "seq_gone.zip: the server has no such file (HTTP 404), nothing was downloaded" in missing.stderr
    monkeypatch.setenv("EAS_VO_DATA_URL", closed_port_url())
    down = run_eas_vo("fetch", "seq_a", env=dict(os.environ))
    assert down.returncode == 1 and down.stderr.count("\n") == 1, down.stderr
    assert "cannot reach the server, nothing was downloaded; offline: copy seq_a.zip into " in down.stderr
    assert "EAS_VO_DATA_DIR" in down.stderr and "EAS_VO_DATA_URL" in down.stderr  # the ways out
    assert _leftovers(data) == [] and hits["seq_a.zip"] == 0


def test_offline_a_local_zip_that_is_not_the_published_one_says_so_and_is_kept(site, tmp_path, monkeypatch):
    """A zip in the data folder whose MD5 differs, and no server: the error names that file,
    both MD5s and the ways out, not only the server; the file is left as it was."""
    import os

    data, md5s, _, _ = site
    data.mkdir()
    (data / "seq_a.zip").write_bytes(b"a partial download")
    monkeypatch.setenv("EAS_VO_DATA_URL", closed_port_url())
    done = run_eas_vo("fetch", "seq_a", env=dict(os.environ))
    assert done.returncode == 1 and done.stderr.count("\n") == 1, done.stderr
    assert f"{data / 'seq_a.zip'}: does not match its MD5 {md5s['seq_a']} (found " in done.stderr
    assert "cannot reach the server" in done.stderr and "EAS_VO_DATA_DIR" in done.stderr
    assert (data / "seq_a.zip").read_bytes() == b"a partial download"


def test_a_fetched_file_gets_the_users_umask(site):
    import os
    import stat

    old = os.umask(0o022)
    try:
        path = ecd_catalogue.fetch("seq_a")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


@pytest.mark.parametrize("as_url", [False, True], ids=["folder", "file-url"])
def test_a_local_mirror_is_copied_verified(site, data_server, tmp_path, monkeypatch, as_url):
    """EAS_VO_DATA_URL as a folder of the zips (a path or file://): copied, MD5-checked, kept
    once; a zip that does not match says so in its own line; one the mirror lacks too."""
    data, md5s, _, hits = site
    import shutil

    mirror = tmp_path / "mirror dir"  # a copy of what the server publishes, its name needing quoting as a URL
    shutil.copytree(data_server[0], mirror)
    monkeypatch.setenv("EAS_VO_DATA_URL", mirror.as_uri() if as_url else str(mirror))
    path = ecd_catalogue.fetch("seq_a")
    assert path == data / "seq_a.zip" and path.read_bytes() == (mirror / "seq_a.zip").read_bytes()
    assert hits["seq_a.zip"] == 0 and _leftovers(data) == ["seq_a.zip"]
    path.unlink()
    (mirror / "seq_a.zip").write_bytes(b"not the zip")
    with pytest.raises(
        EasVoError, match=r"seq_a.zip: does not match its MD5 [0-9a-f]{32} \(found [0-9a-f]{32}\); nothing was kept"
    ):
        ecd_catalogue.fetch("seq_a")
    assert _leftovers(data) == []
    (mirror / "seq_a.zip").unlink()
    with pytest.raises(EasVoError, match="seq_a.zip: not in the local mirror"):
        ecd_catalogue.fetch("seq_a")
    monkeypatch.setenv("EAS_VO_DATA_URL", str(tmp_path / "nowhere"))
    with pytest.raises(EasVoError, match="no such folder"):
        ecd_catalogue.fetch("seq_a")
