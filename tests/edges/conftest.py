"""Fixtures of the edge tests (synthetic EPIs and light fields; helpers in edges_helpers)."""

from __future__ import annotations

import pytest
from edges_helpers import plane_light_field, step_epi, texture_1d


@pytest.fixture
def make_step_epi():
    return step_epi


@pytest.fixture
def make_texture():
    return texture_1d


@pytest.fixture
def make_plane():
    return plane_light_field
