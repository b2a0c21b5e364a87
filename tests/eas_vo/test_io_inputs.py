"""Outputs never replace a command's inputs, however the two paths are spelled: through a link
into a dataset folder, as a hard link, or inside a folder that holds one; and an --out whose
links loop is a one-line error."""

import os

import pytest

from eas_vo.errors import EasVoError
from eas_vo.io.outputs import check_output_file, check_output_folder, refuse_inputs, resolved_out


@pytest.fixture
def dataset(tmp_path):
    """A dataset folder whose events.txt is a link to a file kept elsewhere."""
    elsewhere = tmp_path / "store"
    elsewhere.mkdir()
    (elsewhere / "events.txt").write_text("0.1 1 2 1\n")
    folder = tmp_path / "seq"
    folder.mkdir()
    (folder / "events.txt").symlink_to(elsewhere / "events.txt")
    (folder / "images.txt").write_text("0.0 images/0.png\n")
    return folder


def test_an_output_file_that_a_dataset_file_links_to_is_refused(dataset, tmp_path):
    out = resolved_out(tmp_path / "store" / "events.txt")
    with pytest.raises(EasVoError, match=r"is the dataset .*seq \(its events.txt\), or inside it"):
        refuse_inputs(out, [("the dataset", str(dataset))], out_is_file=True)


def test_an_output_file_hard_linked_to_an_input_is_refused(tmp_path):
    calibration = tmp_path / "calib.xml"
    calibration.write_text("<dv/>")
    os.link(calibration, tmp_path / "gallery.png")
    with pytest.raises(EasVoError, match="is dataset.calibration"):
        refuse_inputs(
            resolved_out(tmp_path / "gallery.png"), [("dataset.calibration", str(calibration))], out_is_file=True
        )


def test_an_output_folder_holding_where_a_dataset_file_leads_is_refused(dataset, tmp_path):
    with pytest.raises(EasVoError, match=r"holds the dataset .*\(its events.txt\)"):
        refuse_inputs(resolved_out(tmp_path / "store"), [("the dataset", str(dataset))])


def test_an_output_folder_reached_through_a_second_mount_of_an_input_is_refused(tmp_path, monkeypatch):
    """Two paths, one folder (a bind mount; here, (device, inode) made to say so)."""
    ground_truth = tmp_path / "a" / "gt.txt"
    ground_truth.parent.mkdir()
    ground_truth.write_text("0 0 0 0 0 0 0 1\n")
    other = tmp_path / "b"
    other.mkdir()
    real_stat = os.stat

    def stat(path, *args, **kwargs):
        return real_stat(tmp_path / "a" if os.fspath(path) == os.fspath(other) else path, *args, **kwargs)

    monkeypatch.setattr(os, "stat", stat)
    with pytest.raises(EasVoError, match="holds dataset.ground_truth"):
        refuse_inputs(other, [("dataset.ground_truth", str(ground_truth))])


def test_outputs_beside_the_inputs_are_allowed(dataset, tmp_path):
    refuse_inputs(resolved_out(tmp_path / "run"), [("the dataset", str(dataset)), ("the --config", None)])
    refuse_inputs(resolved_out(tmp_path / "gallery.png"), [("the dataset", str(dataset))], out_is_file=True)
    refuse_inputs(
        resolved_out(dataset / "runs" / "one"), [("the dataset", str(dataset))]
    )  # a new folder inside the dataset's


@pytest.mark.parametrize(
    "check", [lambda out: check_output_folder(out, True), lambda out: check_output_file(out, True), resolved_out]
)
def test_an_out_whose_links_loop_is_one_line_naming_it(tmp_path, check):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    with pytest.raises(EasVoError, match=r"--out .*a/x: its symbolic links form a loop"):
        check(tmp_path / "a" / "x")
