"""Tests of ``hemicube_radiosity/core/light/``."""
