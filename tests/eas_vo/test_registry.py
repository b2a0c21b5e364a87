"""Plugin discovery through entry points, dataset resolution, and a broken installation."""

import importlib
import subprocess
import sys

import pytest

from eas_vo import plugins, registry
from eas_vo.errors import EasVoError
from helpers import REPOSITORY

CONTRACTS = {
    "datasets": plugins.Dataset,
    "frontends": plugins.Frontend,
    "trackers": plugins.Tracker,
    "backends": plugins.Backend,
}


def test_builtins_register_through_entry_points_and_honour_their_contract():
    assert {"original", "histeq", "slice", "ts", "sits", "eas"} <= set(registry.available("frontends"))
    assert {"klt"} <= set(registry.available("trackers"))
    assert {"chain", "gtsam"} <= set(registry.available("backends"))
    assert {"ecd", "rosbag", "synthetic"} <= set(registry.available("datasets"))
    for kind in registry.KINDS:
        for name, cls in registry.available(kind).items():
            assert cls.name == name and cls.description and issubclass(cls, CONTRACTS[kind])
            cls.Config()  # every key has a default


def test_unknown_name_lists_what_is_installed():
    with pytest.raises(EasVoError) as info:
        registry.get("backends", "nope")
    assert str(info.value) == "unknown backend 'nope'; installed: " + ", ".join(registry.available("backends"))


def test_a_dataset_spec_is_resolved_explicitly_or_by_can_open(short_sequence, tmp_path):
    assert registry.resolve_dataset("synthetic:short") == (registry.get("datasets", "synthetic"), "short")
    assert registry.resolve_dataset(f"ecd:{short_sequence}") == (registry.get("datasets", "ecd"), str(short_sequence))
    assert registry.resolve_dataset(str(short_sequence))[0].name == "ecd"
    assert registry.resolve_dataset(str(tmp_path / "x.zip"))[0].name == "ecd"
    assert registry.resolve_dataset(str(tmp_path / "x.bag"))[0].name == "rosbag"
    with pytest.raises(EasVoError, match="dataset not found"):
        registry.resolve_dataset(str(tmp_path / "missing"))
    with pytest.raises(EasVoError, match="names no location after 'ecd:'"):
        registry.resolve_dataset("ecd:")
    with pytest.raises(EasVoError, match=r"no dataset plugin 'npz' \(installed: "):
        registry.resolve_dataset("npz:recording")
    (tmp_path / "empty").mkdir()  # a folder no plugin recognises; ecd: forces the ECD reader and its message
    with pytest.raises(EasVoError, match="no installed dataset plugin can open it"):
        registry.resolve_dataset(str(tmp_path / "empty"))
    (tmp_path / "x.h5").write_bytes(b"")
    with pytest.raises(EasVoError, match="no installed dataset plugin can open it"):
        registry.resolve_dataset(str(tmp_path / "x.h5"))


def test_two_plugins_claiming_one_location_is_an_error(monkeypatch, short_sequence):
    class Greedy(plugins.Dataset):
        name = "greedy"
        description = "claims everything"

        @classmethod
        def can_open(cls, location):
            return True

    datasets = {**registry.available("datasets"), "greedy": Greedy}
    monkeypatch.setattr(registry, "available", lambda kind: datasets if kind == "datasets" else {})
    with pytest.raises(EasVoError, match=r"several dataset plugins can open it \(ecd, greedy\); write NAME:"):
        registry.resolve_dataset(str(short_sequence))
    assert registry.resolve_dataset(f"greedy:{short_sequence}")[0] is Greedy


def test_a_built_in_that_fails_to_import_is_named(monkeypatch):
    """What a source folder shadowing the installed package looks like: the message says so."""
    why = "eas_vo.datasets.ecd:EcdFolderDataset: ModuleNotFoundError: No module named 'eas_vo.datasets'"
    monkeypatch.setattr(registry, "_load", lambda kind: ({}, {"ecd": why} if kind == "datasets" else {}))
    with pytest.raises(EasVoError) as info:
        registry.get("datasets", "ecd")
    message = str(info.value)
    assert message.startswith(
        f"unknown dataset 'ecd'; installed: none; built-in datasets that failed to import: ecd ({why})"
    )
    assert "eas_vo was imported from" in message
    with pytest.raises(EasVoError, match=r"no dataset plugin 'ecd' \(installed: none\); built-in datasets that failed"):
        registry.resolve_dataset("ecd:/some/folder")


def test_datasets_folder_refuses_to_be_a_top_level_package(monkeypatch):
    monkeypatch.syspath_prepend(str(REPOSITORY))
    monkeypatch.delitem(sys.modules, "datasets", raising=False)
    with pytest.raises(ImportError, match="installs as 'eas_vo.datasets'"):
        importlib.import_module("datasets")


def test_names_are_the_installed_plugins_without_importing_them(tmp_path):
    for kind in registry.KINDS:
        assert registry.names(kind) == sorted(registry.available(kind)) == sorted(registry._entry_points(kind))
    with pytest.raises(ValueError, match="unknown plugin kind 'frontend'"):
        registry.names("frontend")
    check = (
        "import sys; from eas_vo import registry; [registry.names(k) for k in registry.KINDS]; "
        "print(sorted(m for m in sys.modules if m.startswith(('eas_vo.frontends', 'eas_vo.trackers', 'eas_vo.backends', "
        "'eas_vo.datasets'))))"
    )
    assert (
        subprocess.run(
            [sys.executable, "-c", check], capture_output=True, text=True, check=True, cwd=tmp_path
        ).stdout.strip()
        == "[]"
    )
