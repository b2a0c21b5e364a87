"""The installed layout: the core `eas_vo/` and the plugin folders beside it install as
`eas_vo.frontends`, `eas_vo.trackers`, `eas_vo.backends`, `eas_vo.datasets` and `eas_vo.configs`;
every subpackage under them is found by setuptools' package discovery (a new one needs no edit).
Everything else about the package is in pyproject.toml."""

from setuptools import find_packages, setup

#: Source folder -> installed package.
ROOTS = {
    "eas_vo": "eas_vo",
    "frontends": "eas_vo.frontends",
    "trackers": "eas_vo.trackers",
    "backends": "eas_vo.backends",
    "datasets": "eas_vo.datasets",
    "configs": "eas_vo.configs",
}

packages, package_dir = [], {}
for folder, package in ROOTS.items():
    for sub in ["", *find_packages(folder)]:
        name = f"{package}.{sub}" if sub else package
        packages.append(name)
        package_dir[name] = f"{folder}/{sub.replace('.', '/')}" if sub else folder

setup(packages=packages, package_dir=package_dir)
