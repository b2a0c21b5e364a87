"""`eas-vo fetch orb-vocabulary` from a loopback server: verified by SHA-1, extracted whole,
fetched once; a mismatching archive leaves nothing."""

import hashlib
import io
import tarfile

from eas_vo.cli.main import main
from eas_vo.slam.orbvoc import NAME, fetch_orb_vocabulary
from helpers import closed_port_url, one_line_failure

TEXT = "10 6 0 0\n0 1 " + "7 " * 32 + "0.5"


def publish(site) -> str:
    """site/ORBvoc.txt.tar.gz holding Vocabulary/ORBvoc.txt, as ORB-SLAM3 publishes it; its SHA-1."""
    data = TEXT.encode()
    with tarfile.open(site / f"{NAME}.tar.gz", "w:gz") as tar:
        info = tarfile.TarInfo(f"Vocabulary/{NAME}")
        info.size = len(data)
        tar.addfile(info, io.BytesIO(data))
    return hashlib.sha1((site / f"{NAME}.tar.gz").read_bytes()).hexdigest()


def test_the_vocabulary_is_fetched_verified_and_once(data_server, tmp_path):
    site, url, _, hits = data_server
    sha1 = publish(site)
    folder = tmp_path / "data"
    for _ in range(2):
        path = fetch_orb_vocabulary(folder, url=f"{url}{NAME}.tar.gz", sha1=sha1)
        assert path == folder / NAME and path.read_text() == TEXT
    assert hits[f"{NAME}.tar.gz"] == 1
    assert sorted(p.name for p in folder.iterdir()) == [NAME]  # the archive is gone


def test_an_archive_that_is_not_the_published_one_is_one_line_and_leaves_nothing(
    data_server, tmp_path, capsys, monkeypatch
):
    site, url, _, _ = data_server
    publish(site)  # not ORB-SLAM3's archive: its SHA-1 differs from the published one
    monkeypatch.setenv("EAS_VO_ORB_VOCABULARY_URL", f"{url}{NAME}.tar.gz")
    folder = tmp_path / "data"
    assert main(["fetch", "orb-vocabulary", "--dir", str(folder)]) == 1
    notice, err = capsys.readouterr().err.splitlines()  # the download's notice, then the error
    assert notice.startswith("eas-vo: fetching ") and err.startswith("eas-vo: error: ")
    assert "does not match its published SHA-1 ad82cc2a05da116bf211192e4748024a19b7606e" in err
    assert not (folder / NAME).exists() and not any(folder.glob("*.tar.gz"))


def test_fetch_names_the_vocabulary_beside_sequences(data_server, tmp_path, capsys, monkeypatch):
    site, url, _, _ = data_server
    publish(site)
    monkeypatch.setenv("EAS_VO_ORB_VOCABULARY_URL", f"{url}{NAME}.tar.gz")
    err = one_line_failure(["fetch", "orb-vocabulary", "no_such_sequence", "--dir", str(tmp_path)], capsys)
    assert "no_such_sequence" in err and not (tmp_path / NAME).exists()  # every name checked before any download


def test_offline_the_error_names_the_ways_out(tmp_path, capsys, monkeypatch):
    """No server: one line naming where to copy ORBvoc.txt, the mirror variable and --vocabulary."""
    monkeypatch.setenv("EAS_VO_ORB_VOCABULARY_URL", f"{closed_port_url()}{NAME}.tar.gz")
    folder = tmp_path / "data"
    assert main(["fetch", "orb-vocabulary", "--dir", str(folder)]) == 1
    err = capsys.readouterr().err.splitlines()[-1]
    assert "cannot reach the server, nothing was downloaded; offline: copy ORBvoc.txt into " in err
    assert "EAS_VO_ORB_VOCABULARY_URL" in err and "--vocabulary FILE" in err and "eas-vo vocabulary" in err
    assert not folder.exists() or not any(folder.iterdir())
