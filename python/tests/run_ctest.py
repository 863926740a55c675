"""CTest entry of the Python tests: pip-installs ./python (Debian's packages only: no build
isolation, no index) into a scratch folder against the build tree's shared libraries, then runs
pytest on python/tests and prints "N passed, N failed". Usage: run_ctest.py BUILD_DIR WORK_DIR."""
import os
import shutil
import subprocess
import sys

build, work = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
here = os.path.dirname(os.path.abspath(__file__))
site = os.path.join(work, "site")
shutil.rmtree(work, ignore_errors=True)
os.makedirs(work)
env = dict(os.environ, RAYPACK_BUILD_DIR=build, PIP_NO_CACHE_DIR="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
# pip builds in the folder it is given: a copy, so the checkout gets no build/ or egg-info
src = os.path.join(work, "src")
shutil.copytree(os.path.dirname(here), src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__", "tests"))
env["RAYPACK_INCLUDE_DIR"] = os.path.join(os.path.dirname(os.path.dirname(here)), "include")
pip = [sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-index", "--no-deps",
       "--target", site, src]
r = subprocess.run(pip, env=env, capture_output=True, text=True)
if r.returncode != 0:
    print(r.stdout + r.stderr)
    print("0 passed, 1 failed (pip install ./python)")
    sys.exit(1)
sys.path.insert(0, site)
os.chdir(work)  # import raypack from site, not from the source folder

import pytest  # noqa: E402


class Count:
    passed = failed = 0

    def pytest_runtest_logreport(self, report):
        if report.when == "call" and report.passed:
            Count.passed += 1
        elif report.failed:
            Count.failed += 1


rc = pytest.main(["-q", "-p", "no:cacheprovider", here], plugins=[Count()])
if rc == pytest.ExitCode.NO_TESTS_COLLECTED:  # 5: nothing ran, which must not read as a pass
    print("pytest collected no tests")
    Count.failed += 1
    rc = 1
print(f"{Count.passed} passed, {Count.failed} failed")
sys.exit(int(rc) if Count.failed == 0 else max(int(rc), 1))
