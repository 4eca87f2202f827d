# SPDX-License-Identifier: GPL-3.0-or-later
"""How a bake runs: user-facing errors (``errors``) and notes (``notes``), progress and
cancellation (``progress``), work on several cores (``parallel``: ordered maps; ``forked``:
worker processes; ``background``: a value made beside the caller; ``native``: BLAS threads and
the heap), form-factor and in-process caches (``cache``), and the time forecast (``forecast``)."""
