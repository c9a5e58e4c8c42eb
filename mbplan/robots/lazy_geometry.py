"""A robot's visual geometry, loaded when something first draws it.

Reading a robot's visual meshes (COLLADA, STL) takes most of the time to load it — 0.3 s of the
UR5's 0.35 s, 0.5 s of the panda's — and only a replay or a page draws them, so a planning
process never pays it: :class:`LazyGeometry` holds how to build the geometry model and builds
it once, at its first :meth:`~LazyGeometry.get`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import pinocchio as pin

Geometry = pin.GeometryModel | None


class LazyGeometry:
    """A geometry model (or None) built by ``build()`` at the first :meth:`get`; thread-safe.
    Pickled as the model it builds."""

    def __init__(self, build: Callable[[], Geometry]) -> None:
        self._build: Callable[[], Geometry] | None = build
        self._value: Geometry = None
        self._lock = threading.Lock()

    def get(self) -> Geometry:
        """The geometry model (built now if it is not yet)."""
        with self._lock:
            if self._build is not None:
                self._value = self._build()
                self._build = None
            return self._value

    def then(self, transform: Callable[[pin.GeometryModel], Geometry]) -> LazyGeometry:
        """The geometry ``transform(model)`` of this one's model (None stays None), built when
        it is first asked for."""

        def build() -> Geometry:
            model = self.get()
            return None if model is None else transform(model)

        return LazyGeometry(build)

    def __reduce__(self) -> tuple[Any, ...]:
        return _built, (self.get(),)


def _built(model: Geometry) -> LazyGeometry:
    geometry = LazyGeometry(lambda: model)
    geometry.get()
    return geometry


def resolved(geometry: Geometry | LazyGeometry) -> Geometry:
    """The geometry model of ``geometry``, built if it is lazy."""
    return geometry.get() if isinstance(geometry, LazyGeometry) else geometry
