"""Plugin discovery through entry points."""

import importlib
import sys

import pytest

from eas_vo import registry
from helpers import REPOSITORY
from eas_vo.errors import EasVoError


def test_builtins_register_through_entry_points():
    assert {"original", "histeq", "slice", "eas"} <= set(registry.available("frontends"))
    assert "chain" in registry.available("backends")
    assert {"ecd", "synthetic"} <= set(registry.available("datasets"))
    for kind in registry.KINDS:
        for name, cls in registry.available(kind).items():
            assert cls.name == name and cls.description and hasattr(cls, "Config")


def test_unknown_name_lists_what_is_installed():
    with pytest.raises(EasVoError, match=r"unknown backend 'nope'; installed: .*chain"):
        registry.get("backends", "nope")


def test_datasets_folder_refuses_to_be_a_top_level_package(monkeypatch):
    monkeypatch.syspath_prepend(str(REPOSITORY))
    monkeypatch.delitem(sys.modules, "datasets", raising=False)
    with pytest.raises(ImportError, match="installs as 'eas_vo.datasets'"):
        importlib.import_module("datasets")
