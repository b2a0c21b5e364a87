"""`eas-vo list`: the installed plugins and their configuration keys."""

from __future__ import annotations

import sys


def add_parser(sub) -> None:
    """`eas-vo list`: its arguments and help, added to `sub`, the command line's subparsers."""
    parser = sub.add_parser(
        "list",
        help="list the installed datasets, frontends, trackers and backends with their config keys",
        description="Every plugin found through the entry-point groups eas_vo.datasets, eas_vo.frontends, "
        "eas_vo.trackers and eas_vo.backends: name, description, config keys with defaults.",
    )
    parser.set_defaults(func=run)


def run(args) -> int:
    """`eas-vo list` on the parsed `args`; returns the exit status."""
    from dataclasses import MISSING, fields

    from eas_vo import registry
    from eas_vo.config import RunConfig

    def config_keys(cls) -> str:
        keys = [
            f"{f.name}={f.default!r}" if f.default is not MISSING else f.name
            for f in fields(cls)
            if f.default is not MISSING or f.default_factory is MISSING
        ]
        return " ".join(keys) if keys else "(none)"

    print(f"run (every run, [run] or --set run.KEY=VALUE):\n  {'':10s} config: {config_keys(RunConfig)}")
    for kind in registry.KINDS:
        for name, why in registry.broken_builtins(kind).items():
            print(f"eas-vo: warning: built-in {kind[:-1]} {name!r} failed to import: {why}", file=sys.stderr)
        print(f"{kind} (entry-point group eas_vo.{kind}):")
        for name, cls in registry.available(kind).items():
            print(f"  {name:10s} {cls.description}")
            print(f"  {'':10s} config: {config_keys(cls.Config)}")
            if kind == "datasets" and cls.catalogue():
                print(f"  {'':10s} fetch: {' '.join(sorted(cls.catalogue()))}")
    return 0
