"""`eas-vo fetch`: Event Camera Dataset sequences or ORB-SLAM3's vocabulary, verified."""

from __future__ import annotations

import sys

#: The `eas-vo fetch` name of ORB-SLAM3's published vocabulary (ORBvoc.txt).
ORB_VOCABULARY = "orb-vocabulary"


def add_parser(sub) -> None:
    """`eas-vo fetch`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "fetch",
        help="download Event Camera Dataset sequences (verified against their published MD5) or ORB-SLAM3's vocabulary",
        description="Download recordings by name (e.g. hdr_boxes hdr_poster; `eas-vo list` shows the catalogue) "
        "as the dataset publishes them, check each against its MD5, and skip those already there and whole. "
        "A download goes to a temporary file moved into place only once verified; an interrupted one is "
        "restarted by the same command. --dataset ecd:NAME then opens it (and fetches it if missing). "
        "`orb-vocabulary` downloads ORB-SLAM3's ORBvoc.txt (checked against the SHA-1 of its archive) for eas-vo slam.",
        epilog="environment: EAS_VO_DATA_DIR (default folder), EAS_VO_DATA_URL (a mirror), "
        "EAS_VO_DATA_REGISTRY (a file of 'name md5' lines replacing the built-in registry), "
        "EAS_VO_ORB_VOCABULARY_URL (a mirror of ORBvoc.txt.tar.gz)",
    )
    parser.add_argument("names", nargs="+", metavar="NAME", help="a sequence name, PLUGIN:NAME, or orb-vocabulary")
    parser.add_argument(
        "--dir", metavar="DIR", help="where to keep them (default: $EAS_VO_DATA_DIR, else the cache's data/)"
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo fetch` on the parsed `args`; returns the exit status."""
    from eas_vo.registry import fetchable

    wanted = [
        fetchable(spec) for spec in args.names if spec != ORB_VOCABULARY
    ]  # every name checked before any download
    if ORB_VOCABULARY in args.names:
        from eas_vo.slam.orbvoc import fetch_orb_vocabulary

        print(f"{ORB_VOCABULARY}: {fetch_orb_vocabulary(args.dir, progress=sys.stderr.isatty())} (verified)")
    for plugin, name in wanted:
        path = plugin.fetch(name, args.dir, progress=sys.stderr.isatty())
        print(f"{name}: {path} (verified)")
    return 0
