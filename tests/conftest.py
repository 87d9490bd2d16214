"""Shared fixtures: both backends, and a cache so that a scene runs once per session."""

from __future__ import annotations

import functools

import pytest

import sliders

BACKENDS = ("fortran", "numpy")


@functools.lru_cache(maxsize=None)
def run(scene: sliders.Scene, backend: str) -> sliders.TiltResult:
    """Tilt a scene once per test session (Scene is frozen and hashable)."""
    return sliders.tilt(scene, backend=backend)


@pytest.fixture(params=BACKENDS)
def backend(request) -> str:
    return request.param
