"""Package discovery and the optional compiled kernel; everything else is in pyproject.toml."""

import os

from setuptools import Extension, find_packages, setup

# Python's own CFLAGS carry -fwrapv and -fno-strict-aliasing (for CPython's sources); the
# kernel relies on neither, and with them its pixel loop measured 10-17% slower.
# -fno-math-errno (nothing reads errno) and -fno-trapping-math (no FP exception is ever
# enabled): with them GCC vectorises sqrtf and if-converts max(x, 0) in the Beier-Neely
# field's loop; neither changes a result (no -ffast-math: every float op stays IEEE).
_CFLAGS = ["/O2"] if os.name == "nt" else ["-O3", "-std=c99", "-Wall", "-fno-wrapv", "-fstrict-aliasing",
                                           "-fno-math-errno", "-fno-trapping-math"]

setup(
    # lipsync.face.models holds only data (the face models and their licence): named here so
    # setuptools ships it as a data package instead of warning that it is not listed.
    packages=find_packages(include=["lipsync", "lipsync.*"]) + ["lipsync.face.models", "lipsync._visemes",
                                                                  "lipsync._configs"],
    package_dir={"lipsync._visemes": "visemes", "lipsync._configs": "configs"},
    # The flow renderer's frame kernel (AVX2 gathers, chosen at run time by CPU), yuv420p
    # conversion and the Beier-Neely field. optional: without a C compiler the build warns
    # and numba's copies of the kernels are used instead.
    ext_modules=[Extension("lipsync.morphing._flowkernel", ["lipsync/morphing/_flowkernel.c"], optional=True,
                           extra_compile_args=_CFLAGS)],
)
