"""`eas-vo slam`: ORB-SLAM3 on a frontend's images, in a child process."""

from __future__ import annotations

import argparse
import sys

from eas_vo.cli.options import (
    add_config,
    add_dataset,
    add_output_options,
    add_quiet,
    add_window,
    dataset_inputs,
    positive_int,
    refuse_inputs_inside,
    shows_progress,
    window_overrides,
)

EPILOG_SLAM = """\
outputs (in --out):
  run_R/frames.csv      per frame: index, t, state (not_initialised, ok, recently_lost, lost, relocalised),
                        tracked map points, the pose ORB-SLAM3 gave then (camera-to-world, its map's frame;
                        empty for a frame it did not track)
  run_R/keyframes.tum   the keyframe trajectory; run_R/trajectory.tum each tracked frame once (untracked ones
                        have no line), both after ORB-SLAM3's final optimisation
  run_R/metrics.json    status (ok: from the first initialisation on, >= 90 % of the frames tracked and the last;
                        never_initialised, lost, crashed), time to first initialisation, fractions tracked,
                        Sim(3) APE of both trajectories [m, rad]
  run_R/settings.yaml, run_R/slam.log   what ORB-SLAM3 read and printed
  summary.md, summary.json              median, min and max over the runs that tracked; ORB features and matches

examples:
  eas-vo vocabulary --dataset synthetic:walk --frontend original --out walk.voc.txt
  eas-vo slam --dataset synthetic:walk --frontend original --vocabulary walk.voc.txt --out slam_walk
  eas-vo fetch orb-vocabulary && eas-vo slam --dataset ecd:hdr_boxes --frontend eas --duration 25 --out slam_boxes
"""


def add_parser(sub) -> None:
    """`eas-vo slam`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "slam",
        help="run monocular ORB-SLAM3 on a frontend's images and score it (the paper's Table 2; extra: slam)",
        description="Feed a frontend's images of the window frame by frame to monocular ORB-SLAM3 (pyorbslam3, "
        "in a child process; settings from the dataset's calibration), --runs times (its threads make each run "
        "differ), and score each run's keyframe and all-frame trajectories against ground truth after Sim(3) "
        "alignment. Each frame is sent once ORB-SLAM3's mapping threads are idle, so a busy machine changes how long a run "
        "takes, not what it tracks. A run that never initialises, loses track or crashes is reported as such.",
        epilog=EPILOG_SLAM,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_dataset(parser)
    parser.add_argument("--frontend", metavar="NAME", help="image source (default eas)")
    parser.add_argument(
        "--vocabulary",
        metavar="FILE",
        help="DBoW2 text vocabulary (default: $PYORBSLAM3_VOCAB, else ORBvoc.txt from eas-vo fetch orb-vocabulary)",
    )
    parser.add_argument("--runs", type=positive_int, default=5, help="runs (default 5, as the ORB-SLAM papers report)")
    add_config(parser)
    add_window(parser)
    add_quiet(parser)
    add_output_options(parser, required=True)
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo slam` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo.io.outputs import check_output_folder
    from eas_vo.io.text import figure_text
    from eas_vo.slam.process import find_vocabulary, require_extra
    from eas_vo.slam.run import run_slam
    from eas_vo.slam.scores import SUMMARISED

    require_extra()
    vocabulary = find_vocabulary(args.vocabulary)
    config = config_mod.resolve(
        args.config, {"dataset": args.dataset, "frontend": args.frontend, **window_overrides(args)}, args.assignments
    )
    out = check_output_folder(args.out, replace=args.overwrite)
    refuse_inputs_inside(
        out,
        dataset_inputs(config.run.dataset, config.dataset),
        ("the --config", args.config),
        ("the --vocabulary", str(vocabulary)),
    )
    done = run_slam(config, out, str(vocabulary), args.runs, progress=shows_progress(args), replace=args.overwrite)
    statuses = ", ".join(f"{n} {s}" for s, n in done["statuses"].items())
    print(
        f"ORB-SLAM3 on {done['frames']} {done['frontend']} images of {done['dataset']}: {done['runs']} run(s), {statuses} -> {out}"
    )
    for key, text in SUMMARISED:
        s = done[key]
        if s:
            print(
                f"  {text}: median {figure_text(s['median'], 4)} (min {figure_text(s['min'], 4)}, "
                f"max {figure_text(s['max'], 4)}, {s['n']} run(s))"
            )
    if not done["statuses"].get("ok"):
        print("  no run tracked: " + "; ".join(f"run {m['run']} {m['status']}" for m in done["per_run"]))
    for line in done["crashed"]:
        print(f"eas-vo: error: {line}", file=sys.stderr)
    return 1 if done["crashed"] else 0
