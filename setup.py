"""Packages: ``airspace_sim`` and the repository's ``plugins/`` folder installed as
``airspace_sim_plugins`` (the shipped ``kalman`` and ``mvp`` plugins, registered by the
entry points in pyproject.toml). Everything else is in pyproject.toml; a mapped folder is
the one thing its ``[tool.setuptools]`` table cannot combine with package discovery."""

from setuptools import find_packages, setup

setup(
    packages=find_packages(include=["airspace_sim*"]) + ["airspace_sim_plugins"],
    package_dir={"airspace_sim_plugins": "plugins"},
)
