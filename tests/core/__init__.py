"""Tests of the pure-NumPy core, one folder per stage package of ``hemicube_radiosity/core/``."""
