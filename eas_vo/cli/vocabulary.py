"""`eas-vo vocabulary`: an ORB vocabulary trained on a recording's images."""

from __future__ import annotations

from eas_vo.cli.options import (
    add_config,
    add_dataset,
    add_quiet,
    add_window,
    dataset_inputs,
    positive_int,
    refuse_inputs_inside,
    shows_progress,
    window_overrides,
)


def add_parser(sub) -> None:
    """`eas-vo vocabulary`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "vocabulary",
        help="train a DBoW2 ORB vocabulary (ORB-SLAM's text format) on a sequence's own images",
        description="Extract ORB descriptors (ORB-SLAM's extractor settings) from every image of a frontend over "
        "the window and cluster them by hierarchical k-majority on Hamming distance, as DBoW2 does; word weights "
        "are inverse document frequencies over the images. Small by default: k=10 branches, L=4 levels (up to "
        "10^4 words; ORB-SLAM's ORBvoc.txt has 10^6).",
    )
    add_dataset(parser)
    parser.add_argument("--frontend", metavar="NAME", help="image source (default eas)")
    parser.add_argument("--k", type=positive_int, default=10, help="branches per node (default 10)")
    parser.add_argument("--levels", type=positive_int, default=4, help="levels L (default 4)")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the clustering (default 0)")
    add_config(parser)
    add_window(parser)
    add_quiet(parser)
    parser.add_argument("--out", required=True, metavar="FILE", help="the vocabulary file to write")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing --out if it is a vocabulary (never one of the inputs)",
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo vocabulary` on the parsed `args`; returns the exit status."""
    from eas_vo import config as config_mod
    from eas_vo.io.outputs import check_output_file, refuse_foreign_file
    from eas_vo.slam.train import train_vocabulary

    config = config_mod.resolve(
        args.config, {"dataset": args.dataset, "frontend": args.frontend, **window_overrides(args)}, args.assignments
    )
    out = check_output_file(args.out, replace=args.overwrite)
    refuse_inputs_inside(
        out, dataset_inputs(config.run.dataset, config.dataset), ("the --config", args.config), out_is_file=True
    )
    refuse_foreign_file(out, "DBoW2 vocabulary")
    done = train_vocabulary(config, out, args.k, args.levels, args.seed, progress=shows_progress(args))
    print(
        f"wrote a vocabulary of {done['nodes']} nodes ({done['words']} words, k={args.k}, L={args.levels}) from "
        f"{done['descriptors']} ORB descriptors of {done['images']} {done['frontend']} images of {done['dataset']} to {out}"
    )
    return 0
