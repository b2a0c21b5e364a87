"""What the ground truth scores of a run: metrics.json and the summary say how many frames
over what span, warn under 90 %, and a ground truth that can score no frame is refused
before any work."""

from __future__ import annotations

import json

from eas_vo.cli.main import main
from helpers import one_line_failure


def keep_poses(folder, keep) -> None:
    """groundtruth.txt with only the rows whose time satisfies keep(t)."""
    path = folder / "groundtruth.txt"
    rows = [line for line in path.read_text().splitlines() if keep(float(line.split()[0]))]
    path.write_text("\n".join(rows) + "\n")


def test_a_late_ground_truth_scores_half_the_frames_and_says_so(sequence_copy, tmp_path, capsys):
    keep_poses(sequence_copy, lambda t: t >= 0.5)
    assert main(["run", "--dataset", str(sequence_copy), "--duration", "1", "--out", str(tmp_path / "run")]) == 0
    said = capsys.readouterr()
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert (metrics["frames"], metrics["frames_evaluated"]) == (20, 10)  # frames 0.01-0.96 s, poses from 0.5 s
    assert metrics["frames_scored_fraction"] == 0.5 and metrics["frames_in_ground_truth_gaps"] == 0
    start, end = metrics["ground_truth_span_s"]
    assert abs(start - 0.49) < 1e-9 and abs(end - 1.985) < 1e-9  # from the run's first frame, at 0.01 s
    warning = [w for w in metrics["data_warnings"] if "ground truth scores only" in w]
    assert warning == [
        (
            "the ground truth scores only 10 of the run's 20 frames (50 %, under 90 %): it spans 0.490 to 1.985 s "
            "of the run's 0 to 0.950 s; the APE describes those frames only"
        )
    ]
    assert f"eas-vo: warning: {warning[0]}" in said.err
    assert "deg; 10 of 20 frames), " in said.out  # the summary counts them; the warning gives the span


def test_a_ground_truth_too_sparse_to_score_any_frame_is_refused_before_any_work(sequence_copy, tmp_path, capsys):
    keep_poses(sequence_copy, lambda t: t in (0.2, 1.3))  # two poses 1.1 s apart
    err = one_line_failure(["run", "--dataset", str(sequence_copy), "--out", str(tmp_path / "run")], capsys)
    assert (
        f"{sequence_copy / 'groundtruth.txt'}: the ground truth (2 poses, 0.200-1.300 s) scores none of the 40" in err
    )
    assert "up to 1.1 s apart" in err and not (tmp_path / "run").exists()
