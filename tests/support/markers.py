"""Skip conditions shared by tests, each defined once. (The markers ``cycles``, ``slow`` and
``blender`` are registered in ``pytest.ini`` and set per module with ``pytestmark``.)"""
import pytest

from hemicube_radiosity.core.rays import embree_available

needs_embree = pytest.mark.skipif(not embree_available(), reason="embreex is not installed")
