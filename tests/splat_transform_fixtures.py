"""The splat-transform versions the interoperability tests run against, as fixtures shared by
tests/formats/test_interop_splat_transform.py and tests/edit/test_edit_interop.py.

``stfiles`` is tests/data/splat_transform_files.py (also a script, so loaded by path);
``version`` is each pinned version, skipped with the reason where it is not installed;
``exe`` its command line.  Import the fixtures into a test module to use them.
"""

from __future__ import annotations

import importlib.util

import pytest

from helpers import REPO

_spec = importlib.util.spec_from_file_location(
    "splat_transform_files", REPO / "tests" / "data" / "splat_transform_files.py")
stfiles = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(stfiles)


@pytest.fixture(scope="module", params=stfiles.VERSIONS)
def version(request):
    why = stfiles.missing(request.param)
    if why:
        pytest.skip(why)
    return request.param


@pytest.fixture(scope="module")
def exe(version):
    return stfiles.executable(version)
