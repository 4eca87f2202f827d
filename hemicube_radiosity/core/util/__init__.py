# SPDX-License-Identifier: GPL-3.0-or-later
"""Helpers with no radiosity knowledge: sparse rows, k nearest neighbours, distinct rows,
geometry, sampling and the luminance weights of a colour."""
