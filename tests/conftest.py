"""Shared fixtures: the default database (built once per session; the cache folder follows
LMM_STUDIO_CACHE, as everywhere else) and its features."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def db():
    from lmm.data.build import load_or_build
    return load_or_build()[0]


@pytest.fixture(scope="session")
def features(db):
    from lmm.features import build_features
    return build_features(db)
