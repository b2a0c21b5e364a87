"""Bundled configurations; `--config NAME` selects `NAME.toml` from here."""
