"""Tests of ``hemicube_radiosity/core/mesh/``."""
