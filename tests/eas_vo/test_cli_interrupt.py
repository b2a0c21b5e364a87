"""Interrupted runs keep every processed frame; existing results are not overwritten by accident."""

import json
import os
import signal
import sys

import numpy as np
import pytest

from eas_vo.cli.main import main
from eas_vo.frontends.intensity import OriginalFrontend


@pytest.mark.parametrize("how,code", [("sigint", 130), ("sigterm", 143)])
def test_signal_mid_run_leaves_valid_partial_outputs(short_sequence, tmp_path, monkeypatch, capsys, how, code):
    original_call = OriginalFrontend.__call__

    def interrupting(self, sample):
        if sample.index == 12:
            if how == "sigint":
                raise KeyboardInterrupt
            os.kill(os.getpid(), signal.SIGTERM)
        return original_call(self, sample)

    monkeypatch.setattr(OriginalFrontend, "__call__", interrupting)
    out = tmp_path / "run"
    assert (
        main(["run", "--dataset", str(short_sequence), "--frontend", "original", "--out", str(out), "--quiet"]) == code
    )
    err = capsys.readouterr().err
    assert (
        err
        == f"eas-vo run: interrupted; the 12 frames processed so far were written to {out} (metrics.json: partial)\n"
    )
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["partial"] is True and metrics["frames"] == 12
    assert len((out / "trajectory.tum").read_text().splitlines()) == 12
    assert len((out / "frames.csv").read_text().splitlines()) == 13  # header + 12 frames
    assert np.isfinite(metrics["ape_mean_rad"])
    assert not list(out.glob(".*.tmp"))  # no half-written file left behind
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the handler is restored


def test_existing_results_need_overwrite(short_sequence, tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["run", "--dataset", str(short_sequence), "--frontend", "original", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    assert main(argv) == 1
    assert "is not empty; choose another folder or add --overwrite" in capsys.readouterr().err
    assert main(argv + ["--overwrite"]) == 0


def test_compare_reruns_a_partial_cell(short_sequence, tmp_path, capsys):
    out = tmp_path / "cmp"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original",
        "--backends",
        "chain",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    assert main(argv) == 0
    (metrics_path,) = out.rglob("metrics.json")
    metrics = json.loads(metrics_path.read_text())
    metrics["partial"] = True
    metrics_path.write_text(json.dumps(metrics))
    capsys.readouterr()
    assert main(argv) == 0
    assert "1 cells (1 run, 0 already complete" in capsys.readouterr().out
    assert json.loads(metrics_path.read_text())["partial"] is False


def test_compare_interrupted_writes_its_table_and_resumes(short_sequence, tmp_path, monkeypatch, capsys):
    from eas_vo.experiments import grid

    real_run_cell = grid.run_cell
    calls = []

    def interrupting(cell, *args):
        calls.append(cell)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_run_cell(cell, *args)

    monkeypatch.setattr(grid, "run_cell", interrupting)
    out = tmp_path / "cmp"
    argv = [
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original,slice,eas",
        "--backends",
        "chain",
        "--out",
        str(out),
        "--jobs",
        "1",
        "--quiet",
    ]
    assert main(argv) == 130
    err = capsys.readouterr().err
    assert (
        err
        == f"eas-vo compare: interrupted; the table of the 1 finished cells was written to {out}; the same command resumes the rest\n"
    )
    rows = json.loads((out / "table.json").read_text())
    assert [r["status"] for r in rows] == ["ok", "not run", "not run"]
    monkeypatch.setattr(grid, "run_cell", real_run_cell)
    capsys.readouterr()
    assert main(argv) == 0
    assert "3 cells (2 run, 1 already complete, 0 failed)" in capsys.readouterr().out


def test_sigterm_to_a_parallel_compare_stops_it_at_once_without_orphans(short_sequence, tmp_path):
    """SIGTERM to the parent of --jobs 2 as the first cells finish: exit 143 within seconds, the
    table of what finished written, queued cells not started, and no worker left running."""
    import subprocess
    import sys
    import tempfile
    import time

    out = tmp_path / "cmp"
    argv = [
        sys.executable,
        "-m",
        "eas_vo",
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original,slice,eas",
        "--backends",
        "chain",
        "--sweep",
        "tracker.max_corners=100,200,300,400",
        "--out",
        str(out),
        "--jobs",
        "2",
        "--quiet",
    ]
    parent = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tempfile.gettempdir()
    )
    deadline = time.monotonic() + 120
    while (
        not [f for f in out.glob("*/*/metrics.json") if not f.parent.name.startswith(".")]
        and time.monotonic() < deadline
    ):
        time.sleep(0.05)
    parent.send_signal(signal.SIGTERM)
    stopped = time.monotonic()
    assert parent.wait(timeout=60) == 143
    assert time.monotonic() - stopped < 15
    err = parent.stderr.read()
    assert err.startswith("eas-vo compare: interrupted; the table of the ") and err.count("\n") == 1, err
    statuses = [r["status"] for r in json.loads((out / "table.json").read_text())]
    assert "ok" in statuses and "not run" in statuses and len(statuses) == 12
    time.sleep(0.5)
    survivors = subprocess.run(["pgrep", "-f", str(out)], capture_output=True, text=True).stdout.split()
    assert survivors == [], survivors


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="workers end with their parent through Linux's prctl")
def test_kill_9_of_a_parallel_compare_leaves_no_worker_and_the_rerun_completes(short_sequence, tmp_path):
    import subprocess
    import tempfile
    import time

    out = tmp_path / "cmp"
    argv = [
        sys.executable,
        "-m",
        "eas_vo",
        "compare",
        "--dataset",
        str(short_sequence),
        "--frontends",
        "original,slice,eas",
        "--backends",
        "chain",
        "--sweep",
        "tracker.max_corners=100,200,300,400",
        "--out",
        str(out),
        "--jobs",
        "2",
        "--quiet",
    ]
    parent = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=tempfile.gettempdir())
    deadline = time.monotonic() + 120
    while (
        not [f for f in out.glob("*/*/metrics.json") if not f.parent.name.startswith(".")]
        and time.monotonic() < deadline
    ):
        time.sleep(0.05)
    parent.kill()
    parent.wait(timeout=10)
    time.sleep(1.0)
    survivors = subprocess.run(["pgrep", "-f", str(out)], capture_output=True, text=True).stdout.split()
    assert survivors == [], survivors
    rerun = subprocess.run(argv, capture_output=True, text=True, cwd=tempfile.gettempdir(), timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert "12 cells (" in rerun.stdout and "0 failed" in rerun.stdout
