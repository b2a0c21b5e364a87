"""`eas-vo render`: every frontend's image of chosen frames (the paper's Fig. 1)."""

from eas_vo import config, registry
from eas_vo.cli.main import main
from eas_vo.experiments.gallery import frontend_images


def test_render_draws_a_gallery_of_every_installed_frontend(short_sequence, tmp_path, capsys):
    """Every frontend that makes an image (not no_image, for event-only trackers); asking for
    no_image is a one-line error."""
    out = tmp_path / "gallery.png"
    assert main(["render", "--dataset", str(short_sequence), "--frames", "3,20", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    n_frontends = sum(registry.get("frontends", name).makes_images for name in registry.available("frontends"))
    assert n_frontends >= 6
    assert f"2 frame(s) x {n_frontends} frontend(s)" in capsys.readouterr().out
    assert (
        main(
            [
                "render",
                "--dataset",
                str(short_sequence),
                "--frames",
                "3",
                "--frontends",
                "no_image",
                "--out",
                str(tmp_path / "none.png"),
            ]
        )
        == 1
    )
    assert "makes no image" in capsys.readouterr().err


def test_render_images_match_running_each_frontend(short_sequence):
    names, images = frontend_images(str(short_sequence), [5], ["sits", "eas"])
    dataset = registry.open_dataset(str(short_sequence))
    for name in names:
        frontend = registry.get("frontends", name)(config.resolve(None, {"frontend": name}).frontend, dataset.camera)
        for sample in dataset.samples():
            image = frontend(sample)
            if sample.index == 5:
                break
        assert (image == images[(5, name)]).all(), name


def test_render_rejects_missing_frames(short_sequence, capsys):
    assert main(["render", "--dataset", str(short_sequence), "--frames", "3,9999", "--out", "x.png"]) == 1
    assert "frame 9999 does not exist" in capsys.readouterr().err
