"""Tests of ``hemicube_radiosity/core/util/``."""
