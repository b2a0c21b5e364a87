"""`eas-vo evaluate`: an external TUM trajectory scored against a dataset's ground truth."""

from __future__ import annotations

import sys

from eas_vo.cli.options import add_dataset, add_output_options, dataset_inputs, refuse_inputs_inside, seconds
from eas_vo.errors import UsageError


def add_parser(sub) -> None:
    """`eas-vo evaluate`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "evaluate",
        help="score an external TUM trajectory (e.g. ORB-SLAM2's KeyFrameTrajectory.txt) against ground truth",
        description="--protocol evo (default): associate the estimate's poses with the dataset's ground truth "
        "(nearest time within --max-diff), align them (sim3: Umeyama with scale, for monocular SLAM; se3; origin) "
        "and report the translation APE [m] and rotation APE [rad], as evo_ape tum GT EST -as / -a / "
        "--align_origin does; with --out: metrics.json, table2_row.md, groundtruth.tum, estimate_aligned.tum. "
        "--protocol cmax-slam: the event-rotation benchmark's scoring (the first 30 s, ground truth smoothed over "
        "50 ms, aligned at 1 s; absolute RMS [deg] and 1 s relative RMS [deg/s]: docs/rotation_benchmark.md), "
        "as `eas-vo reproduce rotation` scores its own; with --out: metrics.json, rotation_errors.png.",
    )
    add_dataset(parser, help="the dataset the estimate was made on", required=True)
    parser.add_argument("--estimate", required=True, metavar="FILE", help="TUM trajectory: t tx ty tz qx qy qz qw")
    parser.add_argument(
        "--protocol",
        choices=("evo", "cmax-slam"),
        default="evo",
        help="how to score (default evo: evo_ape's APE; cmax-slam: the rotation benchmark's)",
    )
    parser.add_argument("--align", choices=("sim3", "se3", "origin"), help="evo: default sim3 (evo_ape -as)")
    parser.add_argument(
        "--max-diff",
        type=seconds(allow_zero=True),
        metavar="S",
        help="evo: largest time difference of an associated pose pair (default 0.01 s, evo's)",
    )
    parser.add_argument(
        "--label", metavar="TEXT", help="evo: the row's name in table2_row.md (default: the file's name)"
    )
    add_output_options(parser, required=False)
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo evaluate` on the parsed `args`; returns the exit status."""
    from eas_vo.experiments.external import evaluate_estimate, evaluate_protocol
    from eas_vo.io.outputs import check_output_folder
    from eas_vo.io.text import figure_text

    if args.out:
        out = check_output_folder(args.out, replace=args.overwrite)
        refuse_inputs_inside(out, dataset_inputs(args.dataset), ("the --estimate", args.estimate))
    if args.protocol == "cmax-slam":
        given = [f"--{k.replace('_', '-')}" for k in ("align", "max_diff", "label") if getattr(args, k) is not None]
        if given:
            raise UsageError(
                f"{', '.join(given)}: evo's options; --protocol cmax-slam aligns and scores by its own rules"
            )
        m = evaluate_protocol(args.dataset, args.estimate, args.out, replace=args.overwrite)
        relative = (
            f"{figure_text(m['relative_rms_deg_s'], 4)} deg/s ({m['spans_scored']} spans)"
            if m["relative_rms_deg_s"] is not None
            else "none (the estimate covers no whole 1 s span)"
        )
        print(
            f"{args.estimate} vs {m['dataset']} (cmax-slam protocol, {m['poses_scored']} poses scored): absolute "
            f"RMS {figure_text(m['absolute_rms_deg'], 4)} deg, relative over 1 s RMS {relative}"
            + (f" -> {args.out}" if args.out else "")
        )
        return 0
    m = evaluate_estimate(
        args.dataset,
        args.estimate,
        args.align or "sim3",
        0.01 if args.max_diff is None else args.max_diff,
        args.out,
        args.label,
        replace=args.overwrite,
    )
    for line in m["warnings"]:
        print(f"eas-vo: warning: {line}", file=sys.stderr)
    print(
        f"{args.estimate} vs {m['dataset']} ({m['align']}, {m['matched_poses']} of {m['estimate_poses']} poses matched, "
        f"scale {m['scale']:.4g}): translation APE mean {figure_text(m['ape_trans_mean_m'], 4)} m, "
        f"RMSE {figure_text(m['ape_trans_rmse_m'], 4)} m; rotation APE mean {m['ape_rot_mean_rad']:.4f} rad"
        + (f" -> {args.out}" if args.out else "")
    )
    return 0
