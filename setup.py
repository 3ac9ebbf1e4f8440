"""Package discovery and the optional compiled kernel; everything else is in pyproject.toml."""

from setuptools import Extension, find_packages, setup

setup(
    packages=find_packages(include=["lipsync", "lipsync.*"]) + ["lipsync._visemes", "lipsync._configs"],
    package_dir={"lipsync._visemes": "visemes", "lipsync._configs": "configs"},
    # The flow renderer's frame kernel (AVX2 gathers, chosen at run time by CPU). optional:
    # without a C compiler the build warns and the renderer uses its numba kernel instead.
    ext_modules=[Extension("lipsync._flowkernel", ["lipsync/_flowkernel.c"], optional=True,
                           extra_compile_args=["-O3", "-std=c99", "-Wall"])],
)
