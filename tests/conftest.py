import os
from pathlib import Path

import numpy as np
import pytest

# Tests never touch the user's cache.
os.environ.setdefault("INVFACE_CACHE", str(Path(__file__).parent / ".cache"))

import invface  # noqa: E402

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
ICT = SHARED / "data" / "ict-facekit"
SMALL_RESOLUTION = 0.3


@pytest.fixture(scope="session")
def small_model():
    """The template at a small resolution (~10k tets), anatomy only, built once per session."""
    return invface.template.build(resolution=SMALL_RESOLUTION, expressions=False)


@pytest.fixture(scope="session")
def small_expressive_model():
    """The small template with its simulated expression blendshapes."""
    return invface.template.build(resolution=SMALL_RESOLUTION)


@pytest.fixture(scope="session")
def default_model():
    """The default-size template (cached between sessions in tests/.cache)."""
    return invface.template.build(resolution=1.0, expressions=False)


def load_ict_neutral():
    """ICT-FaceKit neutral vertices (V,3) in metres, or skip when ../shared is absent."""
    if not (ICT / "neutral.obj").exists():
        pytest.skip("ICT-FaceKit data (../shared/data/ict-facekit) is not available")
    V = [list(map(float, line.split()[1:4])) for line in open(ICT / "neutral.obj") if line.startswith("v ")]
    return np.array(V) * 0.01
