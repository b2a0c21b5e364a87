"""Shared fixtures: an isolated cache, no network but loopback, a short simulated sequence,
and a local HTTP server for downloads.

The suite tests the *installed* eas-vo (editable or not): the repository root is taken
off `sys.path` first, so that `python -m pytest` run from the root (which puts the
current folder on the path) never imports the source folder `eas_vo/` in place of the
installed package, whose plugins live in `eas_vo.frontends` etc.
"""

from __future__ import annotations

import ipaddress
import os
import shutil
import socket
import sys
from pathlib import Path

import pytest

_ROOT = Path(__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if Path(p or os.curdir).resolve() != _ROOT]
try:
    import eas_vo  # noqa: F401
except ImportError:
    raise pytest.UsageError("eas-vo is not installed in this Python: pip install -e '.[test]' (see README)") from None

# No test reaches the internet: downloads go to a closed loopback port unless a test serves them,
# and this process's sockets refuse any address but loopback.
os.environ["EAS_VO_DATA_URL"] = "http://127.0.0.1:9/"
os.environ.pop("EAS_VO_DATA_REGISTRY", None)
os.environ.pop("EAS_VO_DATA_DIR", None)
_connect = socket.socket.connect


def _loopback_only(sock, address):
    host = address[0] if isinstance(address, tuple) else None
    if host is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
        if not ipaddress.ip_address(host.split("%")[0]).is_loopback:
            raise OSError(f"the test suite refuses a connection to {host}: no network outside loopback")
    return _connect(sock, address)


socket.socket.connect = _loopback_only


@pytest.fixture(scope="session", autouse=True)
def isolated_cache(tmp_path_factory):
    """Keep the user's cache out of the tests (and the tests' sequences out of the user's cache).

    The cache lives in pytest's base temporary folder, so it goes with it: at once after a
    passing session (tmp_path_retention_policy = "failed"), and after a failed or killed one
    when later sessions prune all but the newest few (about 3 GB each). Parallel workers
    (pytest-xdist) share one, in the base folder of the whole session, so each sequence is
    simulated and each event cache built once (both are written whole, then renamed).
    """
    if "EAS_VO_CACHE_DIR" in os.environ:
        yield
        return
    base = tmp_path_factory.getbasetemp()
    cache = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "cache"
    cache.mkdir(exist_ok=True)
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("EAS_VO_CACHE_DIR", str(cache))
        yield


@pytest.fixture(scope="session")
def short_sequence(tmp_path_factory) -> Path:
    """A 2-second simulated sequence (seed 3), written once per test session."""
    from eas_vo.datasets.simulator import SimConfig, simulate

    folder = tmp_path_factory.mktemp("sim") / "short"
    simulate(SimConfig(duration_s=2.0, seed=3), folder)
    return folder


@pytest.fixture(scope="session")
def walk_vocabulary(tmp_path_factory) -> Path:
    """A DBoW2 vocabulary (k=10, L=4) trained by `eas-vo vocabulary` on the original frames of
    synthetic:walk_short (the translating walk, simulated once per session into the cache)."""
    from eas_vo.cli.main import main

    path = tmp_path_factory.mktemp("vocabulary") / "walk.voc.txt"
    assert (
        main(
            ["vocabulary", "--dataset", "synthetic:walk_short", "--frontend", "original", "--out", str(path), "--quiet"]
        )
        == 0
    )
    return path


@pytest.fixture
def sequence_copy(short_sequence, tmp_path) -> Path:
    """A private copy of the short sequence that a test may damage."""
    dst = tmp_path / "seq"
    shutil.copytree(short_sequence, dst)
    return dst


@pytest.fixture
def data_server(tmp_path):
    """A thread serving a temporary folder on 127.0.0.1, as a dataset's download site.

    Yields (folder, url, faults, hits): put files in `folder`; `faults[name]` is a list of
    what the next GETs of `name` get instead of the file ("drop": the connection closes
    half-way; "corrupt": one byte changed); `hits[name]` counts GETs.
    """
    import functools
    import http.server
    import threading
    from collections import Counter, defaultdict

    folder = tmp_path / "site"
    folder.mkdir()
    faults: dict[str, list[str]] = defaultdict(list)
    hits: Counter = Counter()

    class Handler(http.server.SimpleHTTPRequestHandler):
        def do_GET(self):
            name = self.path.lstrip("/")
            hits[name] += 1
            fault = faults[name].pop(0) if faults[name] else None
            path = folder / name
            if fault is None or not path.is_file():
                return super().do_GET()
            body = bytearray(path.read_bytes())
            self.send_response(200)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            if fault == "drop":
                self.wfile.write(body[: len(body) // 2])
                self.wfile.flush()
                self.close_connection = True
                self.connection.shutdown(socket.SHUT_RDWR)
                return
            body[len(body) // 3] ^= 0xFF
            self.wfile.write(bytes(body))

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(folder)))
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield folder, f"http://127.0.0.1:{server.server_address[1]}/", faults, hits
    finally:
        server.shutdown()
        server.server_close()
