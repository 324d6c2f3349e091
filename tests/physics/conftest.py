"""The physics packages' shared fixture: ICT's face area."""

import pytest

from mimica.data import ICT_FACE_AREA_VERTICES, ICTModel


@pytest.fixture(scope="module")
def face():
    """ICT's face area (its 9,409 vertices), the model the simulation tests drive."""
    return ICTModel(ICT_FACE_AREA_VERTICES)
