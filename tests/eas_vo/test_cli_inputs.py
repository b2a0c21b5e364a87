"""Every command that writes refuses an --out that would replace one of its inputs, however it
is reached (a link in the dataset folder, a calibration or ground truth named by --set), and
says in one line when the links of --out loop."""

import shutil

import pytest

from helpers import mark_as_eas_vo_output, one_line_failure


@pytest.fixture
def linked_sequence(short_sequence, tmp_path):
    """The short sequence with its events.txt a link to a copy kept in `store/`."""
    store = tmp_path / "store"
    store.mkdir()
    shutil.copy(short_sequence / "events.txt", store / "events.txt")
    seq = tmp_path / "seq"
    shutil.copytree(short_sequence, seq, ignore=shutil.ignore_patterns(".*", "events.txt"))
    (seq / "events.txt").symlink_to(store / "events.txt")
    return seq


def test_render_never_writes_over_the_file_a_dataset_link_leads_to(linked_sequence, tmp_path, capsys):
    events = tmp_path / "store" / "events.txt"
    kept = events.read_bytes()
    err = one_line_failure(
        [
            "render",
            "--dataset",
            str(linked_sequence),
            "--frames",
            "1",
            "--frontends",
            "original",
            "--out",
            str(events),
            "--overwrite",
        ],
        capsys,
    )
    assert "is the dataset" in err and "(its events.txt)" in err and events.read_bytes() == kept


def test_vocabulary_never_writes_over_the_calibration_given_with_set(short_sequence, tmp_path, capsys):
    calibration = tmp_path / "calib.txt"
    shutil.copy(short_sequence / "calib.txt", calibration)
    kept = calibration.read_bytes()
    err = one_line_failure(
        [
            "vocabulary",
            "--dataset",
            str(short_sequence),
            "--frontend",
            "eas",
            "--duration",
            "0.5",
            "--k",
            "2",
            "--levels",
            "1",
            "--set",
            f"dataset.calibration={calibration}",
            "--out",
            str(calibration),
            "--overwrite",
            "--quiet",
        ],
        capsys,
    )
    assert "is dataset.calibration" in err and calibration.read_bytes() == kept


def test_run_never_replaces_a_folder_holding_the_ground_truth_given_with_set(short_sequence, tmp_path, capsys):
    earlier = tmp_path / "earlier"
    earlier.mkdir()
    ground_truth = earlier / "groundtruth.tum"
    shutil.copy(short_sequence / "groundtruth.txt", ground_truth)
    mark_as_eas_vo_output(earlier)
    err = one_line_failure(
        [
            "run",
            "--dataset",
            str(short_sequence),
            "--duration",
            "0.2",
            "--set",
            f"dataset.ground_truth={ground_truth}",
            "--out",
            str(earlier),
            "--overwrite",
            "--quiet",
        ],
        capsys,
    )
    assert (
        "holds dataset.ground_truth" in err
        and ground_truth.read_bytes() == (short_sequence / "groundtruth.txt").read_bytes()
    )


@pytest.mark.parametrize(
    "command",
    [
        ["run"],
        ["compare"],
        ["render", "--frames", "1"],
        ["vocabulary"],
        ["convert"],
        ["export"],
        ["simulate"],
        ["evaluate", "--estimate", "trajectory.tum"],
        ["reproduce", "table1"],
    ],
)
def test_an_out_whose_links_loop_is_one_line_naming_it(short_sequence, tmp_path, capsys, command):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    dataset = [] if command[0] in ("simulate", "reproduce") else ["--dataset", str(short_sequence)]
    err = one_line_failure([*command, *dataset, "--out", str(tmp_path / "a" / "out")], capsys)
    assert f"--out {tmp_path / 'a' / 'out'}: its symbolic links form a loop" in err


@pytest.mark.parametrize(
    "command",
    [
        ["render", "--frames", "1", "--frontends", "original"],
        ["vocabulary", "--frontend", "eas", "--duration", "0.5", "--k", "2", "--levels", "1"],
    ],
)
def test_overwrite_replaces_only_a_file_of_the_kind_the_command_writes(short_sequence, tmp_path, capsys, command):
    """A note anywhere is never replaced by --overwrite; the command's own earlier file is."""
    note = tmp_path / "notes.txt"
    note.write_text("important\n")
    args = [command[0], "--dataset", str(short_sequence), *command[1:]]
    err = one_line_failure([*args, "--out", str(note), "--overwrite"], capsys)
    assert "so not a file eas-vo wrote" in err and note.read_text() == "important\n"
    from eas_vo.cli.main import main

    own = tmp_path / "own"
    assert main([*args, "--out", str(own)]) == 0
    assert main([*args, "--out", str(own), "--overwrite"]) == 0
