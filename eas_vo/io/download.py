"""One-line errors for a failed download through pooch, naming the way out offline."""

from __future__ import annotations

from eas_vo.errors import EasVoError


def download_error(exc: Exception, url: str, checksum: str, offline: str) -> EasVoError:
    """The user's error for pooch's `exc` while fetching `url`: a checksum mismatch (`checksum`
    names the expected one), a server that cannot be reached (with `offline`, what to do without
    one), or another failure with its first line."""
    import requests

    detail = str(exc).splitlines()[0] if str(exc) else "no detail"
    if isinstance(exc, ValueError) and "hash" in detail.lower():
        return EasVoError(f"{url}: the download does not match its {checksum}; nothing was kept")
    if isinstance(exc, (requests.ConnectionError, requests.Timeout)):
        return EasVoError(f"{url}: cannot reach the server, nothing was downloaded; offline: {offline}")
    return EasVoError(f"{url}: download failed, nothing was kept ({type(exc).__name__}: {detail})")
