"""Tests of ``hemicube_radiosity/core/runtime/``."""
