"""Tests of ``hemicube_radiosity/core/solve/``."""
