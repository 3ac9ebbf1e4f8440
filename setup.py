"""Package discovery only; everything else is in pyproject.toml."""

from setuptools import find_packages, setup

setup(
    packages=find_packages(include=["lipsync", "lipsync.*"]) + ["lipsync._visemes", "lipsync._configs"],
    package_dir={"lipsync._visemes": "visemes", "lipsync._configs": "configs"},
)
