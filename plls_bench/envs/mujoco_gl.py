"""Choose a headless OpenGL backend for MuJoCo before it is imported: EGL, then OSMesa.

MuJoCo reads ``MUJOCO_GL`` once, at import, so the probe runs in a subprocess. The choice is
exported to ``os.environ``, so vector-env workers inherit it and the probe runs once per process tree.
"""
from __future__ import annotations

import os
import subprocess
import sys

BACKENDS = ("egl", "osmesa")
_PROBE = "import mujoco; c = mujoco.GLContext(16, 16); c.make_current(); c.free()"


class RenderingUnavailable(RuntimeError):
    """No headless OpenGL backend works on this machine."""


def probe(backend: str) -> bool:
    env = {**os.environ, "MUJOCO_GL": backend, "PYOPENGL_PLATFORM": backend}
    try:
        done = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return False
    return done.returncode == 0


def ensure_mujoco_gl() -> str:
    """Set ``MUJOCO_GL`` (unless the user did) to the first backend that works; return it."""
    chosen = os.environ.get("MUJOCO_GL")
    if chosen:
        return chosen
    for backend in BACKENDS:
        if probe(backend):
            os.environ["MUJOCO_GL"] = backend
            os.environ.setdefault("PYOPENGL_PLATFORM", backend)
            return backend
    raise RenderingUnavailable(
        "no headless OpenGL backend works for MuJoCo (tried MUJOCO_GL=egl and osmesa); "
        "install the Debian packages libegl1 libgl1-mesa-dri libosmesa6 (./reproduce.sh does, as root)")
