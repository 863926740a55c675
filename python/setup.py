# pip install ./python (Debian: /usr/bin/python3 -m pip install --no-build-isolation --no-index ./python)
# builds raypack._raypack against libraypack: RAYPACK_PREFIX=<install prefix>, or RAYPACK_BUILD_DIR=
# <build folder>, or the checkout's build/release, or pkg-config raypack-render (see raypack/_build.py).
from setuptools import setup

setup(
    name="raypack",
    version="0.1.0",
    description="raypack ray tracing engine: scenes from numpy arrays and files, ray queries, rendering",
    packages=["raypack"],
    package_data={"raypack": ["_raypack.c"]},
    setup_requires=["cffi>=1.0"],
    install_requires=["cffi>=1.0", "numpy"],
    cffi_modules=["raypack/_build.py:ffibuilder"],
    zip_safe=False,
)
