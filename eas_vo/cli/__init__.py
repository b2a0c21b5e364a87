"""The command line, one module a command; `eas_vo.cli.main` is its entry point."""
