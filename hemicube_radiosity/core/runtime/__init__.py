# SPDX-License-Identifier: GPL-3.0-or-later
"""How a bake runs: user-facing errors, progress and cancellation, work on several cores,
form-factor and in-process caches, and the time forecast."""
