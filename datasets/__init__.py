"""Dataset plugins; installed as `eas_vo.datasets`."""

if __name__ != "eas_vo.datasets":
    raise ImportError(
        f"this folder is eas-vo's dataset plugins and installs as 'eas_vo.datasets', "
        f"but it was imported as {__name__!r} (probably from the repository root). "
        "Install the project (pip install -e .) and import eas_vo.datasets; "
        "the top-level name 'datasets' belongs to an unrelated package."
    )
