"""Tests of ``hemicube_radiosity/core/output/``."""
