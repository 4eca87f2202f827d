"""Tests of ``hemicube_radiosity/core/form_factors/``."""
