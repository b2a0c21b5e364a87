"""`python -m eas_vo`: the `eas-vo` command."""

from eas_vo.cli.main import main

raise SystemExit(main())
