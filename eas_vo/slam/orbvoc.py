"""`eas-vo fetch orb-vocabulary`: ORB-SLAM3's published ORB vocabulary (ORBvoc.txt, 10^6 words)
into the data folder, downloaded through pooch against the archive's published SHA-1."""

from __future__ import annotations

import logging
import os
import tarfile
from pathlib import Path

from eas_vo.errors import EasVoError
from eas_vo.io.atomic import atomic_file
from eas_vo.io.download import download_error

logger = logging.getLogger(__name__)

#: Where ORB-SLAM3 publishes it, and the SHA-1 of the archive: both as pyorbslam3's vocab.py
#: (0.1.1) gives them. EAS_VO_ORB_VOCABULARY_URL names a mirror of the same archive.
URL = "https://github.com/UZ-SLAMLab/ORB_SLAM3/raw/master/Vocabulary/ORBvoc.txt.tar.gz"
SHA1 = "ad82cc2a05da116bf211192e4748024a19b7606e"
NAME = "ORBvoc.txt"


def fetch_orb_vocabulary(
    folder: str | Path | None = None, progress: bool = False, url: str | None = None, sha1: str = SHA1
) -> Path:
    """FOLDER/ORBvoc.txt (default: the data folder), downloaded and extracted unless there. The
    archive is verified by pooch before anything is extracted; the text file appears whole
    or not at all; the archive is removed after."""
    import pooch
    import requests

    from eas_vo.datasets.ecd_catalogue import data_dir

    folder = Path(folder or data_dir())
    target = folder / NAME
    if target.is_file():
        return target
    url = url or os.environ.get("EAS_VO_ORB_VOCABULARY_URL") or URL
    logger.info(f"fetching {url} (about 40 MB; ORBvoc.txt is 139 MB) into {folder}")
    pooch.get_logger().setLevel(logging.WARNING)
    try:
        archive = Path(
            pooch.retrieve(url, known_hash=f"sha1:{sha1}", fname=f"{NAME}.tar.gz", path=folder, progressbar=progress)
        )
    except (ValueError, requests.RequestException, OSError) as exc:
        offline = (
            f"copy {NAME} into {folder}, set EAS_VO_ORB_VOCABULARY_URL to a copy of the archive, "
            "or train one with `eas-vo vocabulary` and give it as --vocabulary FILE"
        )
        raise download_error(exc, url, f"published SHA-1 {sha1}", offline) from None
    try:
        with tarfile.open(archive, "r:gz") as tar:
            member = next((m for m in tar.getmembers() if m.isfile() and m.name.endswith(NAME)), None)
            if member is None:
                raise EasVoError(f"{url}: the archive holds no {NAME}")
            with tar.extractfile(member) as src, atomic_file(target) as dst:
                while chunk := src.read(1 << 20):
                    dst.write(chunk)
    except (tarfile.TarError, EOFError) as exc:
        raise EasVoError(f"{archive}: not a readable tar.gz ({exc})") from None
    finally:
        archive.unlink(missing_ok=True)
    return target
