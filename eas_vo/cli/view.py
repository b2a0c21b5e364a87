"""`eas-vo view`: a run folder's Rerun recording (RUN/run.rrd), and the line saying how to open it."""

from __future__ import annotations

import sys


def add_parser(sub) -> None:
    """`eas-vo view`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "view",
        help="write a run's Rerun recording (images, tracked points, orientations, errors) into its folder",
        description="Write RUN/run.rrd, a Rerun recording of the run in RUN: each frame's image and tracked "
        "points (the frames replayed from RUN/config.toml), its status, the estimated and true orientations, "
        "the rotation error and its predicted sigma over time, and one window of events. Open it with "
        '`rerun RUN/run.rrd` or in Rerun\'s web viewer. Needs rerun-sdk: pip install "eas-vo[view]".',
    )
    parser.add_argument("run_folder", metavar="RUN", help="a folder eas-vo run wrote (its --out)")
    add_spawn(parser)
    parser.set_defaults(func=run)


def add_spawn(parser) -> None:
    """--spawn: also open the recording in Rerun's viewer."""
    parser.add_argument("--spawn", action="store_true", help="also open the recording in Rerun's viewer (a window)")


def run(args) -> int:
    """`eas-vo view` on the parsed `args`; returns the exit status."""
    write_and_say(args.run_folder, args.spawn)
    return 0


def write_and_say(folder, spawn: bool) -> None:
    """Write the run folder's recording (pipeline.view.write_recording), say in one line where it
    is and how to open it (a warning first if the replay tracked otherwise), and with `spawn` open it."""
    from eas_vo.io.rerun_log import open_in_viewer, viewer_url
    from eas_vo.pipeline.view import write_recording

    written = write_recording(folder)
    if written.replay_differs:
        print(
            f"eas-vo: warning: the replayed tracking found other correspondence counts than frames.csv at "
            f"{written.replay_differs} of {written.frames} frames (as where the run tracked again without "
            "the gyro); the points shown are the replay's",
            file=sys.stderr,
        )
    print(f"wrote {written.path} ({written.frames} frames): open it with `rerun {written.path}` or in {viewer_url()}")
    if spawn:
        open_in_viewer(written.path)
